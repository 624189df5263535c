//! The check every printing binary's test makes (one copy, not one per
//! test file): run a command whose standard output has no reader (`| head`
//! gone before it writes) and see it end by SIGPIPE, as a C tool does,
//! not by a panic in `println!`.

/// Runs `command` with its standard output a pipe whose reading end is
/// already closed, so its first write fails every time.
///
/// # Errors
/// What went wrong, with its standard error: the command was not ended by
/// SIGPIPE (13), or it printed a panic; or it could not be started.
#[cfg(unix)]
pub fn ends_by_sigpipe(command: &mut std::process::Command) -> Result<(), String> {
    use std::os::unix::process::ExitStatusExt as _;
    let (reader, writer) = std::io::pipe().map_err(|e| format!("a pipe: {e}"))?;
    drop(reader);
    let out = command
        .stdout(writer)
        .output()
        .map_err(|e| format!("starting it: {e}"))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.signal() != Some(13) || stderr.contains("panicked") {
        return Err(format!("ended by {:?}: {stderr}", out.status));
    }
    Ok(())
}
