//! The simulated board behind a pseudo-terminal: a thread reads the pty's
//! master side and answers through it, so the driver talks to it through
//! its ordinary serial port (the slave side, e.g. `/dev/pts/7`), byte for
//! byte as to a real board.

use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use rustix::io::Errno;

use crate::error::{Result, RoboclawError};
use crate::link::wait_readable;
use crate::sim::{Clock, SimBoard};

/// How long the server waits for bytes before it moves the model on anyway
/// (the serial timeout fires without traffic).
const IDLE_POLL: Duration = Duration::from_millis(2);

fn pty_err(what: &'static str) -> impl FnOnce(Errno) -> RoboclawError {
    move |e| RoboclawError::Pty {
        what,
        cause: e.into(),
    }
}

/// Opens a pseudo-terminal in raw mode; returns its master side and the
/// path of its slave side.
pub fn open_pty() -> Result<(OwnedFd, PathBuf)> {
    use rustix::pty::{OpenptFlags, grantpt, openpt, ptsname, unlockpt};
    use rustix::termios::{OptionalActions, tcgetattr, tcsetattr};
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY | OpenptFlags::CLOEXEC)
        .map_err(pty_err("openpt"))?;
    grantpt(&master).map_err(pty_err("grantpt"))?;
    unlockpt(&master).map_err(pty_err("unlockpt"))?;
    let name = ptsname(&master, Vec::new()).map_err(pty_err("ptsname"))?;
    // Raw from the start: no echo of the answers back to the board, no
    // line discipline touching 0x0a, 0x0d or 0x7f (the driver's serial port
    // sets raw mode too when it opens the slave).
    let mut termios = tcgetattr(&master).map_err(pty_err("tcgetattr"))?;
    termios.make_raw();
    tcsetattr(&master, OptionalActions::Now, &termios).map_err(pty_err("tcsetattr"))?;
    let path = {
        use std::os::unix::ffi::OsStrExt;
        PathBuf::from(std::ffi::OsStr::from_bytes(name.as_bytes()))
    };
    Ok((master, path))
}

/// A running simulated board on a pseudo-terminal.
pub struct PtyServer {
    path: PathBuf,
    board: Arc<Mutex<SimBoard>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl PtyServer {
    /// Opens a pseudo-terminal and serves `board` on it, on the time of
    /// `clock`, until dropped.
    pub fn spawn(board: SimBoard, clock: Arc<dyn Clock>) -> Result<Self> {
        let (master, path) = open_pty()?;
        let board = Arc::new(Mutex::new(board));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let board = Arc::clone(&board);
            let stop = Arc::clone(&stop);
            std::thread::Builder::new()
                .name("roboclaw-sim".into())
                .spawn(move || serve(&master, &board, clock.as_ref(), &stop))
                .map_err(|cause| RoboclawError::Pty {
                    what: "thread",
                    cause,
                })?
        };
        Ok(Self {
            path,
            board,
            stop,
            thread: Some(thread),
        })
    }

    /// The slave side: the "serial port" to open.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The board (lock it to inject faults or read its state).
    pub fn board(&self) -> &Arc<Mutex<SimBoard>> {
        &self.board
    }

    /// Runs `f` on the locked board.
    pub fn with_board<R>(&self, f: impl FnOnce(&mut SimBoard) -> R) -> Option<R> {
        self.board.lock().ok().map(|mut b| f(&mut b))
    }
}

impl Drop for PtyServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn write_all(fd: &OwnedFd, mut bytes: &[u8]) {
    while !bytes.is_empty() {
        match rustix::io::write(fd, bytes) {
            Ok(n) => bytes = &bytes[n..],
            Err(Errno::INTR | Errno::AGAIN) => {}
            // Nobody on the slave side: the answer is lost, as on a wire.
            Err(_) => return,
        }
    }
}

fn serve(master: &OwnedFd, board: &Mutex<SimBoard>, clock: &dyn Clock, stop: &AtomicBool) {
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::SeqCst) {
        let readable = wait_readable(master.as_fd(), IDLE_POLL).unwrap_or(false);
        let n = if readable {
            // EIO: no process has the slave open (yet, or any more).
            rustix::io::read(master, &mut buf).unwrap_or_else(|_| {
                std::thread::sleep(IDLE_POLL);
                0
            })
        } else {
            0
        };
        let Ok(mut board) = board.lock() else {
            return;
        };
        let now = clock.now_ns();
        if n == 0 {
            board.advance(now);
        } else {
            board.receive(&buf[..n], now, |answer| write_all(master, answer));
        }
    }
}
