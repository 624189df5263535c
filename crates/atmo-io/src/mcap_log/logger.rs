//! The logger thread and its non-blocking handle.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU16, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::{MESSAGE_ENCODING, PROFILE, SCHEMA_ENCODING};
use crate::error::{IoError, Result};
use crate::msg::{
    ActuatorMotors, DiagnosticArray, DiagnosticStatus, Header, KeyValue, MpcStatus, Odometry,
    OffboardControlMode, PilotInput, RosMessage, SimTruth, TickInputs, TickTiming, Time, Twist,
    VehicleOdometry, encode, schema_text,
};

/// Topic of the logger's own health (dropped and written counts).
pub const LOGGER_TOPIC: &str = "/atmo/logger";

/// Chunk compression.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Compression {
    #[default]
    Zstd,
    Lz4,
    None,
}

/// Logger settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoggerOptions {
    /// Records the channel holds before `try_log` drops (default 4096, 27 s
    /// of 150 Hz status).
    pub queue_capacity: usize,
    /// Longest time between two flushes (default 0.5 s, at most 1 s).
    pub flush_period: Duration,
    pub compression: Compression,
    /// Bytes after which a chunk is closed even before the flush period.
    pub chunk_size: u64,
}

impl Default for LoggerOptions {
    fn default() -> Self {
        Self {
            queue_capacity: 4096,
            flush_period: Duration::from_millis(500),
            compression: Compression::Zstd,
            chunk_size: 1 << 20,
        }
    }
}

/// A message kind the logger carries. The fixed-size kinds are copied into
/// the channel as they are (no allocation); the kinds with strings or
/// sequences are boxed (allocation: not for the control thread).
#[derive(Debug, Clone)]
// Fixed-size records are stored inline on purpose: boxing them would
// allocate on the control thread. The queue's slots are preallocated.
#[allow(clippy::large_enum_variant)]
pub enum LogPayload {
    MpcStatus(MpcStatus),
    PilotInput(PilotInput),
    TickTiming(TickTiming),
    TickInputs(TickInputs),
    SimTruth(SimTruth),
    VehicleOdometry(VehicleOdometry),
    ActuatorMotors(ActuatorMotors),
    OffboardControlMode(OffboardControlMode),
    Twist(Twist),
    Odometry(Box<Odometry>),
    DiagnosticArray(Box<DiagnosticArray>),
}

impl LogPayload {
    fn encode(&self, out: &mut Vec<u8>) -> Result<()> {
        match self {
            Self::MpcStatus(m) => encode(m, out),
            Self::PilotInput(m) => encode(m, out),
            Self::TickTiming(m) => encode(m, out),
            Self::TickInputs(m) => encode(m, out),
            Self::SimTruth(m) => encode(m, out),
            Self::VehicleOdometry(m) => encode(m, out),
            Self::ActuatorMotors(m) => encode(m, out),
            Self::OffboardControlMode(m) => encode(m, out),
            Self::Twist(m) => encode(m, out),
            Self::Odometry(m) => encode(m.as_ref(), out),
            Self::DiagnosticArray(m) => encode(m.as_ref(), out),
        }
    }
}

/// A message type the logger accepts.
pub trait Loggable: RosMessage {
    fn to_payload(&self) -> LogPayload;
}

macro_rules! loggable {
    ($ty:ident) => {
        impl Loggable for $ty {
            fn to_payload(&self) -> LogPayload {
                LogPayload::$ty(*self)
            }
        }
    };
    (boxed $ty:ident) => {
        impl Loggable for $ty {
            fn to_payload(&self) -> LogPayload {
                LogPayload::$ty(Box::new(self.clone()))
            }
        }
    };
}

loggable!(MpcStatus);
loggable!(PilotInput);
loggable!(TickTiming);
loggable!(TickInputs);
loggable!(SimTruth);
loggable!(VehicleOdometry);
loggable!(ActuatorMotors);
loggable!(OffboardControlMode);
loggable!(Twist);
loggable!(boxed Odometry);
loggable!(boxed DiagnosticArray);

/// A registered channel of message type `M` (a typed id, `Copy`).
pub struct Channel<M> {
    id: u16,
    _type: PhantomData<fn() -> M>,
}

impl<M> Clone for Channel<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Channel<M> {}
impl<M> std::fmt::Debug for Channel<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Channel({})", self.id)
    }
}

#[allow(clippy::large_enum_variant)] // see LogPayload
enum Command {
    Register {
        id: u16,
        topic: String,
        type_name: &'static str,
    },
    Message {
        channel: u16,
        log_time: u64,
        publish_time: u64,
        payload: LogPayload,
    },
    /// A file stored whole in the log (the configuration at start-up).
    Attach {
        name: String,
        media_type: String,
        log_time: u64,
        data: Vec<u8>,
    },
    /// A named map of strings (what the attachments are, their hashes).
    Metadata {
        name: String,
        entries: BTreeMap<String, String>,
    },
    Finish,
}

struct Shared {
    next_channel: AtomicU16,
    accepted: AtomicU64,
    dropped: AtomicU64,
    /// Records the writer has taken off the queue (written or not).
    processed: AtomicU64,
    closed: AtomicBool,
    /// Why the writer stopped before a finish request (a write error such
    /// as a full disk), set once when it has (read without a lock).
    failure: OnceLock<String>,
    topics: Mutex<Vec<String>>,
}

/// The non-blocking side of the logger; cheap to clone and `Send`.
#[derive(Clone)]
pub struct LoggerHandle {
    tx: SyncSender<Command>,
    shared: Arc<Shared>,
}

/// What a finished log holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogSummary {
    pub path: PathBuf,
    /// Messages written (including the logger's own diagnostics).
    pub written: u64,
    /// Records `try_log` dropped because the channel was full or closed.
    pub dropped: u64,
    /// Flushes done (chunks closed on the flush period).
    pub flushes: u64,
}

/// The writer thread; [`LoggerThread::join`] returns its summary.
pub struct LoggerThread {
    join: JoinHandle<Result<LogSummary>>,
}

impl LoggerThread {
    /// Waits for the writer to finish (after [`LoggerHandle::finish`], or
    /// after every handle was dropped) and returns its summary or its error.
    pub fn join(self) -> Result<LogSummary> {
        self.join
            .join()
            .unwrap_or_else(|_| Err(IoError::Logger("the writer thread panicked".into())))
    }
}

/// Entry point: [`McapLogger::spawn`].
pub struct McapLogger;

/// Most numbered names tried beside an existing log.
const MAX_LOG_NUMBER: u32 = 9999;

/// The path a new flight's log takes for `path`: `path` itself unless a
/// regular file (an earlier flight's log) is there, then the first free
/// `STEM.N.EXT` beside it (`flight.mcap` -> `flight.1.mcap`, ...), so that
/// starting the daemon again never overwrites a flight. Anything else at
/// `path` (a device such as `/dev/full`, a FIFO) is written as named; a
/// folder fails when the log is created.
///
/// # Errors
/// [`IoError::File`] when the names up to `STEM.9999.EXT` are all taken.
pub fn unused_log_path(path: &Path) -> Result<PathBuf> {
    let taken = |p: &Path| p.symlink_metadata().is_ok();
    let is_log = path
        .symlink_metadata()
        .is_ok_and(|m| m.is_file() || m.file_type().is_symlink());
    if !is_log {
        return Ok(path.to_path_buf());
    }
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned());
    let ext = path.extension().map(|e| e.to_string_lossy().into_owned());
    for n in 1..=MAX_LOG_NUMBER {
        let name = match (&stem, &ext) {
            (Some(stem), Some(ext)) => format!("{stem}.{n}.{ext}"),
            (Some(stem), None) => format!("{stem}.{n}"),
            _ => format!("log.{n}.mcap"),
        };
        let candidate = path.with_file_name(name);
        if !taken(&candidate) {
            return Ok(candidate);
        }
    }
    Err(IoError::File {
        file: path.to_path_buf(),
        cause: std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!(
                "exists, and so do its numbered names up to {MAX_LOG_NUMBER}: move old logs away"
            ),
        ),
    })
}

impl McapLogger {
    /// Creates `path` and starts the writer thread.
    pub fn spawn(
        path: impl AsRef<Path>,
        options: LoggerOptions,
    ) -> Result<(LoggerHandle, LoggerThread)> {
        let path = path.as_ref().to_path_buf();
        if options.queue_capacity == 0 {
            return Err(IoError::Logger("queue_capacity must be > 0".into()));
        }
        if options.flush_period.is_zero() || options.flush_period > Duration::from_secs(1) {
            return Err(IoError::Logger(format!(
                "flush_period must be in (0, 1] s, got {:?}",
                options.flush_period
            )));
        }
        let file = File::create(&path).map_err(|cause| IoError::File {
            file: path.clone(),
            cause,
        })?;
        let compression = match options.compression {
            Compression::Zstd => Some(mcap::Compression::Zstd),
            Compression::Lz4 => Some(mcap::Compression::Lz4),
            Compression::None => None,
        };
        let writer = mcap::WriteOptions::new()
            .profile(PROFILE)
            .library(concat!("atmo-io ", env!("CARGO_PKG_VERSION")))
            .compression(compression)
            .compression_threads(0)
            .chunk_size(Some(options.chunk_size))
            .create(BufWriter::new(file))
            .map_err(|cause| IoError::Mcap {
                file: path.clone(),
                cause,
            })?;
        let (tx, rx) = sync_channel(options.queue_capacity);
        let shared = Arc::new(Shared {
            next_channel: AtomicU16::new(1),
            accepted: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            processed: AtomicU64::new(0),
            closed: AtomicBool::new(false),
            failure: OnceLock::new(),
            topics: Mutex::new(Vec::new()),
        });
        let handle = LoggerHandle {
            tx,
            shared: Arc::clone(&shared),
        };
        let logger_channel = handle.channel::<DiagnosticArray>(LOGGER_TOPIC)?;
        let thread_path = path.clone();
        let join = std::thread::Builder::new()
            .name("mcap-logger".into())
            .spawn(move || {
                WriterLoop {
                    path: thread_path,
                    writer,
                    rx,
                    shared,
                    flush_period: options.flush_period,
                    logger_channel: logger_channel.id,
                    channels: BTreeMap::new(),
                    written: 0,
                    flushes: 0,
                    buffer: Vec::with_capacity(1024),
                }
                .run()
            })
            .map_err(|e| IoError::Logger(format!("cannot start the writer thread: {e}")))?;
        Ok((handle, LoggerThread { join }))
    }
}

impl LoggerHandle {
    /// Registers a channel for messages of type `M` on `topic` (a ROS 2
    /// topic name starting with `/`). Call at start-up: it may block until
    /// the writer has room and allocates.
    pub fn channel<M: Loggable>(&self, topic: &str) -> Result<Channel<M>> {
        if !topic.starts_with('/') || topic.len() < 2 || topic.contains(char::is_whitespace) {
            return Err(IoError::Logger(format!(
                "topic `{topic}`: expected an absolute ROS 2 name like /atmo/status"
            )));
        }
        // Fail now rather than on the writer thread if a definition is missing.
        schema_text(M::TYPE_NAME)?;
        {
            let mut topics = self
                .shared
                .topics
                .lock()
                .map_err(|_| IoError::Logger("topic registry poisoned".into()))?;
            if topics.iter().any(|t| t == topic) {
                return Err(IoError::Logger(format!(
                    "topic `{topic}` is registered twice"
                )));
            }
            topics.push(topic.to_string());
        }
        let id = self.shared.next_channel.fetch_add(1, Ordering::Relaxed);
        if id == u16::MAX {
            return Err(IoError::Logger("too many channels".into()));
        }
        self.send_setup(Command::Register {
            id,
            topic: topic.to_string(),
            type_name: M::TYPE_NAME,
        })?;
        Ok(Channel {
            id,
            _type: PhantomData,
        })
    }

    /// Stores `data` whole in the log as an MCAP attachment named `name`
    /// (e.g. a config file's text with `media_type` `application/toml`),
    /// stamped `log_time_ns`. Call at start-up: it may block until the
    /// writer has room, and allocates.
    pub fn attach(
        &self,
        name: &str,
        media_type: &str,
        log_time_ns: u64,
        data: Vec<u8>,
    ) -> Result<()> {
        self.send_setup(Command::Attach {
            name: name.to_string(),
            media_type: media_type.to_string(),
            log_time: log_time_ns,
            data,
        })
    }

    /// Writes an MCAP metadata record `name` with `entries`. Start-up only
    /// (may block, allocates).
    pub fn metadata(&self, name: &str, entries: BTreeMap<String, String>) -> Result<()> {
        self.send_setup(Command::Metadata {
            name: name.to_string(),
            entries,
        })
    }

    /// A start-up command. After a write failure (a full disk) it is
    /// counted as dropped like every record, not refused: a log that cannot
    /// be written never stops what it records ([`Self::failed`] tells).
    fn send_setup(&self, command: Command) -> Result<()> {
        match self.tx.send(command) {
            Ok(()) => Ok(()),
            Err(_) if self.failed() => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            Err(_) => Err(IoError::Logger("the writer thread has stopped".into())),
        }
    }

    /// Queues `message` for `channel`, stamped `log_time_ns` (also the
    /// publish time). Never blocks; returns false (and counts a drop) when
    /// the queue is full or the logger has stopped. Allocation-free for the
    /// fixed-size message kinds.
    pub fn try_log<M: Loggable>(&self, channel: Channel<M>, log_time_ns: u64, message: &M) -> bool {
        self.try_log_at(channel, log_time_ns, log_time_ns, message)
    }

    /// [`Self::try_log`] with a separate publish time (the message's own stamp).
    pub fn try_log_at<M: Loggable>(
        &self,
        channel: Channel<M>,
        log_time_ns: u64,
        publish_time_ns: u64,
        message: &M,
    ) -> bool {
        if self.shared.closed.load(Ordering::Relaxed) {
            self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        let command = Command::Message {
            channel: channel.id,
            log_time: log_time_ns,
            publish_time: publish_time_ns,
            payload: message.to_payload(),
        };
        match self.tx.try_send(command) {
            Ok(()) => {
                self.shared.accepted.fetch_add(1, Ordering::Relaxed);
                true
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                false
            }
        }
    }

    /// [`Self::try_log`] for a producer that may wait (a simulation, whose
    /// clock is its own): waits for room in the queue instead of dropping.
    /// Drops and counts only when the logger has stopped or failed, so it
    /// never waits on a dead writer. Not for the control thread.
    pub fn log_waiting<M: Loggable>(
        &self,
        channel: Channel<M>,
        log_time_ns: u64,
        message: &M,
    ) -> bool {
        if self.shared.closed.load(Ordering::Relaxed) || self.failed() {
            self.shared.dropped.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        let mut command = Command::Message {
            channel: channel.id,
            log_time: log_time_ns,
            publish_time: log_time_ns,
            payload: message.to_payload(),
        };
        loop {
            match self.tx.try_send(command) {
                Ok(()) => {
                    self.shared.accepted.fetch_add(1, Ordering::Relaxed);
                    return true;
                }
                Err(TrySendError::Full(back)) if !self.failed() => {
                    command = back;
                    std::thread::sleep(std::time::Duration::from_micros(200));
                }
                Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                    self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                    return false;
                }
            }
        }
    }

    /// Records dropped so far.
    pub fn dropped(&self) -> u64 {
        self.shared.dropped.load(Ordering::Relaxed)
    }

    /// Whether the writer has failed (a write error: the disk is full, the
    /// file system gone). From then on every record is dropped and counted;
    /// the callers go on (the control thread never waits for the log).
    pub fn failed(&self) -> bool {
        self.shared.failure.get().is_some()
    }

    /// The writer's error, once it has [`Self::failed`].
    pub fn failure(&self) -> Option<String> {
        self.shared.failure.get().cloned()
    }

    /// Records accepted into the queue so far.
    pub fn accepted(&self) -> u64 {
        self.shared.accepted.load(Ordering::Relaxed)
    }

    /// Records accepted but not yet taken off the queue by the writer.
    pub fn queued(&self) -> u64 {
        self.accepted()
            .saturating_sub(self.shared.processed.load(Ordering::Relaxed))
    }

    /// Asks the writer to write what is queued and finish the file (summary,
    /// footer). Later `try_log` calls drop. Blocks until the request is queued;
    /// then join the [`LoggerThread`].
    pub fn finish(&self) {
        if !self.shared.closed.swap(true, Ordering::SeqCst) {
            // Fails only if the writer already stopped (error): nothing to do.
            let _ = self.tx.send(Command::Finish);
        }
    }
}

/// A write error of the log `file`: an I/O error as the OS reported it
/// (`No space left on device`), not only as MCAP's generic I/O message.
fn writer_error(file: &Path, source: mcap::McapError) -> IoError {
    match source {
        mcap::McapError::Io(cause) => IoError::File {
            file: file.to_path_buf(),
            cause,
        },
        cause => IoError::Mcap {
            file: file.to_path_buf(),
            cause,
        },
    }
}

struct WriterLoop {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    rx: Receiver<Command>,
    shared: Arc<Shared>,
    flush_period: Duration,
    logger_channel: u16,
    /// Our channel id -> (MCAP channel id, next sequence).
    channels: BTreeMap<u16, (u16, u32)>,
    written: u64,
    flushes: u64,
    buffer: Vec<u8>,
}

impl WriterLoop {
    fn mcap_err(&self, source: mcap::McapError) -> IoError {
        writer_error(&self.path, source)
    }

    fn run(mut self) -> Result<LogSummary> {
        let result = self.run_inner();
        // Whatever happened, stop accepting records.
        self.shared.closed.store(true, Ordering::SeqCst);
        if let Err(e) = &result {
            // What was queued when the write failed is lost too: counted.
            let mut lost = 0;
            while let Ok(command) = self.rx.try_recv() {
                if matches!(command, Command::Message { .. }) {
                    lost += 1;
                }
            }
            self.shared.dropped.fetch_add(lost, Ordering::Relaxed);
            let _ = self.shared.failure.set(e.to_string());
        }
        result?;
        Ok(LogSummary {
            path: self.path.clone(),
            written: self.written,
            dropped: self.shared.dropped.load(Ordering::Relaxed),
            flushes: self.flushes,
        })
    }

    fn run_inner(&mut self) -> Result<()> {
        let mut next_flush = Instant::now() + self.flush_period;
        let mut last_time = 0u64;
        let mut dirty = false;
        loop {
            let wait = next_flush.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(wait) {
                Ok(Command::Finish) | Err(RecvTimeoutError::Disconnected) => break,
                Ok(command) => {
                    if let Some(t) = self.handle(command)? {
                        last_time = last_time.max(t);
                        dirty = true;
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            if Instant::now() >= next_flush {
                if dirty {
                    self.write_health(last_time)?;
                    self.writer.flush().map_err(|e| self.mcap_err(e))?;
                    self.flushes += 1;
                    dirty = false;
                }
                next_flush = Instant::now() + self.flush_period;
            }
        }
        // Write what was queued before the finish request.
        while let Ok(command) = self.rx.try_recv() {
            if let Some(t) = self.handle(command)? {
                last_time = last_time.max(t);
            }
        }
        self.write_health(last_time)?;
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        Ok(())
    }

    /// Handles one command; returns the log time of a written message.
    fn handle(&mut self, command: Command) -> Result<Option<u64>> {
        match command {
            Command::Register {
                id,
                topic,
                type_name,
            } => {
                let schema = schema_text(type_name)?;
                let schema_id = self
                    .writer
                    .add_schema(type_name, SCHEMA_ENCODING, schema.as_bytes())
                    .map_err(|e| self.mcap_err(e))?;
                let channel_id = self
                    .writer
                    .add_channel(schema_id, &topic, MESSAGE_ENCODING, &BTreeMap::new())
                    .map_err(|e| self.mcap_err(e))?;
                self.channels.insert(id, (channel_id, 0));
                Ok(None)
            }
            Command::Message {
                channel,
                log_time,
                publish_time,
                payload,
            } => {
                payload.encode(&mut self.buffer)?;
                self.write(channel, log_time, publish_time)?;
                self.shared.processed.fetch_add(1, Ordering::Relaxed);
                Ok(Some(log_time))
            }
            Command::Attach {
                name,
                media_type,
                log_time,
                data,
            } => {
                let attachment = mcap::Attachment {
                    log_time,
                    create_time: log_time,
                    name,
                    media_type,
                    data: std::borrow::Cow::Owned(data),
                };
                self.writer
                    .attach(&attachment)
                    .map_err(|e| self.mcap_err(e))?;
                Ok(None)
            }
            Command::Metadata { name, entries } => {
                self.writer
                    .write_metadata(&mcap::records::Metadata {
                        name,
                        metadata: entries,
                    })
                    .map_err(|e| self.mcap_err(e))?;
                Ok(None)
            }
            Command::Finish => Ok(None),
        }
    }

    fn write(&mut self, channel: u16, log_time: u64, publish_time: u64) -> Result<()> {
        let Some((channel_id, sequence)) = self.channels.get_mut(&channel) else {
            return Err(IoError::Logger(format!(
                "message for unknown channel {channel}"
            )));
        };
        let header = mcap::records::MessageHeader {
            channel_id: *channel_id,
            sequence: *sequence,
            log_time,
            publish_time,
        };
        *sequence = sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(&header, &self.buffer)
            .map_err(|source| writer_error(&self.path, source))?;
        self.written += 1;
        Ok(())
    }

    /// Writes the logger's health on [`LOGGER_TOPIC`], stamped with the latest
    /// log time seen (the flight-stack clock) and the wall clock in the header.
    fn write_health(&mut self, log_time: u64) -> Result<()> {
        let dropped = self.shared.dropped.load(Ordering::Relaxed);
        let level = if dropped > 0 {
            DiagnosticStatus::WARN
        } else {
            DiagnosticStatus::OK
        };
        let health = DiagnosticArray {
            header: Header {
                stamp: Time::from_ns(crate::wall_clock_ns()),
                frame_id: String::new(),
            },
            status: vec![DiagnosticStatus {
                level,
                name: "atmo/mcap_logger".into(),
                message: if dropped > 0 {
                    format!("{dropped} records dropped (queue full)")
                } else {
                    "ok".into()
                },
                hardware_id: String::new(),
                values: vec![
                    KeyValue {
                        key: "dropped".into(),
                        value: dropped.to_string(),
                    },
                    KeyValue {
                        key: "written".into(),
                        value: self.written.to_string(),
                    },
                ],
            }],
        };
        encode(&health, &mut self.buffer)?;
        self.write(self.logger_channel, log_time, log_time)
    }
}
