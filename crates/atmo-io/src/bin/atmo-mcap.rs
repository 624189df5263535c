//! `atmo-mcap`: tools for the flight stack's MCAP logs.
//!
//! ```text
//! atmo-mcap recover <truncated.mcap> <out.mcap>   make a killed writer's log valid
//! atmo-mcap info <log.mcap>                        messages per topic and time span
//! atmo-mcap summary <log.mcap> --out DIR           summary.json + figure.png (Fig. 5A)
//! ```
//!
//! Both check every chunk's CRC and report the corrupt chunks they skipped.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
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
    /// in flight loses at most its last flush period (`[log] flush_period_ms`).
    Recover {
        /// The truncated log.
        input: PathBuf,
        /// The valid copy to write: a new file (an existing path is refused,
        /// nothing read or written); written whole, then renamed into place.
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
    /// Review a flight from its log alone: write DIR/summary.json (touchdown
    /// tilt, impact speed, max mean thrust, mode sequence...) and
    /// DIR/figure.png (the paper's Fig. 5A), as `atmo-sim fly` does.
    ///
    /// A simulated flight's log carries the plant's truth: the values are
    /// then those of `atmo-sim fly` (the wall time excepted, null here). A
    /// real flight's are the flight stack's own view (estimate, encoder,
    /// contact signal). The log must be finished (else `recover` it first).
    Summary {
        /// The flight log.
        log: PathBuf,
        /// Output folder (created).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// The status topic (the daemon config's ros2.topics.status).
        #[arg(long, default_value = "/atmo/status")]
        status_topic: String,
    },
}

fn main() -> ExitCode {
    // Ends when its reader does (`| head`), as a C tool does, instead of
    // panicking in println!.
    sigpipe::reset();
    let result = match Cli::parse().command {
        Command::Recover { input, output } => refuse_existing(&output)
            .and_then(|()| recover(&input, &output))
            .map(|r| {
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
        Command::Summary {
            log,
            out,
            status_topic,
        } => summary(&log, &out, &status_topic),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("atmo-mcap: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `summary`: the review's summary.json and figure.png in `out`.
fn summary(
    log: &std::path::Path,
    out: &std::path::Path,
    status_topic: &str,
) -> atmo_io::Result<()> {
    use atmo_io::review::figure::write_landing_figure;
    use atmo_io::review::log::{TruthSource, review_log};
    let output = |e: String| atmo_io::IoError::Output(format!("{}: {e}", out.display()));
    // Staged as every output folder: a file or a folder this tool did not
    // write is refused before the log is read; the folder lands whole.
    let staged = atmo_io::output_dir::StagedDir::new(out).map_err(|e| output(e.to_string()))?;
    let review = review_log(log, status_topic)?;
    let mut value = serde_json::to_value(&review.summary).map_err(|e| output(e.to_string()))?;
    if !review.missing.is_empty() {
        for hole in &review.missing {
            eprintln!("atmo-mcap: {}: partial summary: {hole}", log.display());
        }
        eprintln!(
            "atmo-mcap: {}: the landing values are withheld when a hole precedes the touchdown \
             (the first contact may be in it)",
            log.display()
        );
        if let Some(map) = value.as_object_mut() {
            map.insert(
                "partial".into(),
                serde_json::json!({ "missing_ticks": review.missing }),
            );
        }
    }
    let json = serde_json::to_string_pretty(&value).map_err(|e| output(e.to_string()))?;
    std::fs::write(staged.path().join("summary.json"), json + "\n")
        .map_err(|e| output(e.to_string()))?;
    write_landing_figure(
        &staged.path().join("figure.png"),
        &review.trace,
        &review.markers,
        &review.title,
    )?;
    let written = staged.commit().map_err(|e| output(e.to_string()))?;
    let (summary_path, figure_path) = (written.join("summary.json"), written.join("figure.png"));
    let s = &review.summary;
    let fmt = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |v| format!("{v:.2} {unit}"));
    println!(
        "measured on       {}",
        match review.truth {
            TruthSource::Simulation => "the simulator's truth (logged)",
            TruthSource::FlightStack => "the flight stack's view (estimate, encoder, contact)",
        }
    );
    if !review.missing.is_empty() {
        let n: u64 = review
            .missing
            .iter()
            .map(atmo_io::review::log::MissingTicks::count)
            .sum();
        println!(
            "partial           {n} ticks missing in {} span(s): see stderr",
            review.missing.len()
        );
    }
    println!("modes             {}", s.mode_sequence.join(" -> "));
    println!("touchdown tilt    {}", fmt(s.touchdown_tilt_deg, "deg"));
    println!("impact speed      {}", fmt(s.impact_speed_mps, "m/s"));
    println!("max mean thrust   {:.3}", s.max_mean_thrust);
    println!(
        "wrote             {} and {}",
        summary_path.display(),
        figure_path.display()
    );
    Ok(())
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

/// The command line's `recover` writes a new file: an existing path (a
/// file, a link, a device) is refused before anything is read, so that a
/// slip of the arguments cannot replace a log (the library's `recover`
/// replaces its output, atomically).
fn refuse_existing(output: &Path) -> atmo_io::Result<()> {
    if output.symlink_metadata().is_ok() {
        return Err(atmo_io::IoError::File {
            file: output.to_path_buf(),
            cause: std::io::Error::new(
                std::io::ErrorKind::AlreadyExists,
                "exists: recover writes a new file and replaces none (remove it, or name another)",
            ),
        });
    }
    Ok(())
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
