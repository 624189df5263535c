//! `atmo-mcap`: tools for the flight stack's MCAP logs.
//!
//! ```text
//! atmo-mcap recover <truncated.mcap> <out.mcap>   make a killed writer's log valid
//! atmo-mcap info <log.mcap>                        messages per topic and time span
//! ```
//!
//! Both check every chunk's CRC and report the corrupt chunks they skipped.

use std::collections::BTreeMap;
use std::process::ExitCode;

use atmo_io::mcap_log::{read_log_lossy, recover};

const USAGE: &str =
    "usage:\n  atmo-mcap recover <truncated.mcap> <out.mcap>\n  atmo-mcap info <log.mcap>";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args
        .iter()
        .map(String::as_str)
        .collect::<Vec<_>>()
        .as_slice()
    {
        ["recover", input, output] => recover(input, output).map(|r| {
            println!(
                "{}: {} messages on {} channels, last log time {:.3} s{}",
                r.output.display(),
                r.messages,
                r.channels,
                r.last_log_time_ns as f64 * 1e-9,
                r.stopped_by
                    .map(|why| format!(" (input truncated: {why})"))
                    .unwrap_or_default()
            );
            if !r.skipped.is_sound() {
                eprintln!("atmo-mcap: skipped: {}", r.skipped);
            }
        }),
        ["info", log] => read_log_lossy(log).map(|(messages, integrity)| {
            if !integrity.is_sound() {
                eprintln!("atmo-mcap: {log}: skipped: {integrity}");
            }
            let mut topics: BTreeMap<&str, (usize, &str, u64, u64)> = BTreeMap::new();
            for m in &messages {
                let e = topics
                    .entry(&m.topic)
                    .or_insert((0, &m.type_name, u64::MAX, 0));
                e.0 += 1;
                e.2 = e.2.min(m.log_time_ns);
                e.3 = e.3.max(m.log_time_ns);
            }
            for (topic, (count, ty, first, last)) in topics {
                println!(
                    "{topic:<32} {ty:<36} {count:>8} messages {:>10.3} .. {:.3} s",
                    first as f64 * 1e-9,
                    last as f64 * 1e-9
                );
            }
        }),
        ["-h" | "--help"] => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        _ => {
            eprintln!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("atmo-mcap: {e}");
            ExitCode::FAILURE
        }
    }
}
