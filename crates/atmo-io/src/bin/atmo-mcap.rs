//! `atmo-mcap`: tools for the flight stack's MCAP logs.
//!
//! ```text
//! atmo-mcap recover <truncated.mcap> <out.mcap>   make a killed writer's log valid
//! atmo-mcap info <log.mcap>                        messages per topic and time span
//! ```
//!
//! Both check every chunk's CRC and report the corrupt chunks they skipped.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use atmo_io::mcap_log::{LoggedMessage, read_log_lossy, recover};
use clap::{Parser, Subcommand};

/// Tools for the flight stack's MCAP logs (`atmo-daemon run` and
/// `atmo-sim fly` write them; topic /atmo/status carries one
/// atmo_msgs/MpcStatus per control tick).
///
/// Exit status: 0 done, 1 the log could not be read or written (the message
/// names the file), 2 bad command line.
#[derive(Parser)]
#[command(name = "atmo-mcap", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Make the log of a killed writer valid.
    ///
    /// Copies every complete message of INPUT (no summary, no footer, maybe
    /// half a chunk) into OUTPUT, a finished log, and says where and why
    /// reading stopped. A daemon killed
    /// in flight loses at most its last flush period ([log] flush_period_ms).
    Recover {
        /// The truncated log.
        input: PathBuf,
        /// The valid copy to write (must differ from INPUT).
        output: PathBuf,
    },
    /// Messages per topic and the span of their log times.
    ///
    /// Prints one line per topic: its type, how many messages, the first and
    /// last log time (s). The log must be finished (else `recover` it first).
    Info {
        /// The log to read.
        log: PathBuf,
    },
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Recover { input, output } => recover(&input, &output).map(|r| {
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
        Command::Info { log } => read_log_lossy(&log).map(|(messages, integrity)| {
            if !integrity.is_sound() {
                eprintln!("atmo-mcap: {}: skipped: {integrity}", log.display());
            }
            print_topics(&messages);
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("atmo-mcap: {e}");
            ExitCode::FAILURE
        }
    }
}

/// One line per topic: type, message count, first and last log time.
fn print_topics(messages: &[LoggedMessage]) {
    let mut topics: BTreeMap<&str, (usize, &str, u64, u64)> = BTreeMap::new();
    for m in messages {
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
}

#[cfg(test)]
mod tests {
    /// clap's own consistency checks (unique argument ids, defaults that parse).
    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory as _;
        super::Cli::command().debug_assert();
    }
}
