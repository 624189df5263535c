//! Bounded numbers for the command lines (`clap` value parsers, shared by
//! every binary so that one flag means the same limits everywhere).
//!
//! Each parser takes the flag's text and returns the number or a message
//! naming the value and the accepted range; clap adds the flag, so an error
//! reads ``invalid value 'nan' for '--duration <S>': nan is not a finite
//! number of seconds in (0, 604800]``. NaN, infinities and values past the
//! bound are refused instead of running forever or allocating without limit.

/// Longest `atmo-daemon run --duration`, s (one week).
pub const MAX_RUN_DURATION_S: f64 = 7.0 * 24.0 * 3600.0;
/// Longest `explain --demo` recording, s (one hour: 432 000 rows at 120 Hz).
pub const MAX_DEMO_DURATION_S: f64 = 3600.0;
/// Lowest estimate rate, Hz: the plant's sensors (`effects.sensors.rate_hz`)
/// and `explain --demo --rate` take the same range.
pub const MIN_SAMPLE_RATE_HZ: f64 = 1.0;
/// Highest estimate rate, Hz (the same two).
pub const MAX_SAMPLE_RATE_HZ: f64 = 1000.0;
/// Most Monte Carlo runs of one `fly --runs`.
pub const MAX_RUNS: usize = 100_000;
/// Most threads of one `--jobs` (a thread per run, each a flight stack).
pub const MAX_JOBS: usize = 1024;
/// Largest `explain --budget`, s (one day).
pub const MAX_ANALYSIS_BUDGET_S: f64 = 86_400.0;

/// A finite number in `(0, max]` of `unit`.
fn positive_up_to(text: &str, unit: &str, max: f64) -> Result<f64, String> {
    let value: f64 = text
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a number of {unit}"))?;
    if value.is_finite() && value > 0.0 && value <= max {
        Ok(value)
    } else {
        Err(format!(
            "{text} is not a finite number of {unit} in (0, {max}]"
        ))
    }
}

/// `atmo-daemon run --duration`: seconds in `(0, MAX_RUN_DURATION_S]`.
pub fn run_duration_s(text: &str) -> Result<f64, String> {
    positive_up_to(text, "seconds", MAX_RUN_DURATION_S)
}

/// `explain --demo --duration`: seconds in `(0, MAX_DEMO_DURATION_S]`.
pub fn demo_duration_s(text: &str) -> Result<f64, String> {
    positive_up_to(text, "seconds", MAX_DEMO_DURATION_S)
}

/// `explain --demo --rate`: Hz in `[MIN_SAMPLE_RATE_HZ, MAX_SAMPLE_RATE_HZ]`.
pub fn sample_rate_hz(text: &str) -> Result<f64, String> {
    let value = positive_up_to(text, "Hz", MAX_SAMPLE_RATE_HZ)?;
    if value < MIN_SAMPLE_RATE_HZ {
        return Err(format!(
            "{text} is not a finite number of Hz in [{MIN_SAMPLE_RATE_HZ}, {MAX_SAMPLE_RATE_HZ}]"
        ));
    }
    Ok(value)
}

/// `explain --budget`: seconds in `(0, MAX_ANALYSIS_BUDGET_S]`.
pub fn analysis_budget_s(text: &str) -> Result<f64, String> {
    positive_up_to(text, "seconds", MAX_ANALYSIS_BUDGET_S)
}

/// `fly --runs`: a count in `1..=MAX_RUNS`.
pub fn run_count(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_RUNS).contains(&n) => Ok(n),
        _ => Err(format!("{text} is not a number of runs in 1..={MAX_RUNS}")),
    }
}

/// `--jobs`: a thread count in `1..=MAX_JOBS` (0 was taken as 1; a
/// hundred thousand threads would fail to spawn).
pub fn job_count(text: &str) -> Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_JOBS).contains(&n) => Ok(n),
        _ => Err(format!(
            "{text} is not a number of threads in 1..={MAX_JOBS}"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hostile_numbers_are_refused_with_the_value_and_the_range() {
        for text in ["nan", "NaN", "inf", "-inf", "1e300", "0", "-1", "", "abc"] {
            let err = run_duration_s(text).unwrap_err();
            assert!(err.contains(text), "{err}");
        }
        assert!(run_duration_s("1e300").unwrap_err().contains("604800"));
        for text in ["inf", "1e9", "3600.5", "nan"] {
            assert!(demo_duration_s(text).is_err(), "{text}");
        }
        for text in ["inf", "0", "0.5", "1e6", "nan"] {
            assert!(sample_rate_hz(text).is_err(), "{text}");
        }
        assert!(sample_rate_hz("0.5").unwrap_err().contains("[1, 1000]"));
        for text in ["0", "-3", "1e9", "100001", "18446744073709551616"] {
            assert!(run_count(text).is_err(), "{text}");
        }
        for text in ["0", "-1", "1025", "100000", "two"] {
            assert!(job_count(text).is_err(), "{text}");
        }
        assert_eq!(job_count("8"), Ok(8));
    }

    #[test]
    fn ordinary_numbers_pass_unchanged() {
        assert_eq!(run_duration_s("2.5"), Ok(2.5));
        assert_eq!(run_duration_s("604800"), Ok(MAX_RUN_DURATION_S));
        assert_eq!(demo_duration_s("48"), Ok(48.0));
        assert_eq!(sample_rate_hz("120"), Ok(120.0));
        assert_eq!(run_count("200"), Ok(200));
    }
}
