//! The QEMU "bus": a candump drive replayed into the receive path, and the transmit path
//! written back out as candump lines, both over semihosting files on the host.
//!
//! Receive: a frame is put in the receive queue one tick ahead, at the time of the tick before
//! the one it belongs to (the first tick at or after its timestamp, `node::first_tick_us`). The
//! tick drains only frames stamped at or before its own time, so every frame reaches the tick
//! that host replay gives it, whatever the order in which timers that expire together run
//! (docs/architecture.md, "Tick schedule"). The frame keeps its file timestamp as receive time.
use embassy_time::{Instant, Timer};
use semihosting::io::{Read, Seek, SeekFrom, Write};

use super::candump::{self, LineError, LINE_CAP};
use catmodel::can::candump::CandumpError;
use catmodel::can::TimedFrame;
use catmodel_app::{BusReceiver, BusTransmitter, ReplayClock, RxError};

/// Longest input line accepted, bytes.
pub const LINE_MAX: usize = 128;

/// Why the input cannot be replayed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplayError {
    /// The host file could not be read.
    Io,
    /// Line `.0` (1-based) is longer than [`LINE_MAX`].
    LineTooLong(u32),
    /// Line `.0` (1-based) is not a candump frame, for reason `.1`.
    Syntax(u32, CandumpError),
    /// No frame in the input.
    Empty,
}

/// Bytes of a candump file: a host file over semihosting, or the drive bundled in the firmware.
pub enum Source {
    /// A host file.
    File(semihosting::fs::File),
    /// Bytes in flash, read from `pos`.
    Bundled {
        /// The whole file.
        bytes: &'static [u8],
        /// Next byte to read.
        pos: usize,
    },
}

impl Source {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, ReplayError> {
        match self {
            Source::File(file) => file.read(buf).map_err(|_| ReplayError::Io),
            Source::Bundled { bytes, pos } => {
                let rest = bytes.get(*pos..).unwrap_or(&[]);
                let n = rest.len().min(buf.len());
                if let (Some(dst), Some(src)) = (buf.get_mut(..n), rest.get(..n)) {
                    dst.copy_from_slice(src);
                }
                *pos += n;
                Ok(n)
            }
        }
    }

    fn rewind(&mut self) -> Result<(), ReplayError> {
        match self {
            Source::File(file) => file
                .seek(SeekFrom::Start(0))
                .map(|_| ())
                .map_err(|_| ReplayError::Io),
            Source::Bundled { pos, .. } => {
                *pos = 0;
                Ok(())
            }
        }
    }
}

/// Splits a [`Source`] into lines without allocating.
pub struct LineReader {
    source: Source,
    buf: [u8; 1024],
    start: usize,
    end: usize,
    eof: bool,
    line_no: u32,
}

impl LineReader {
    /// Reads `source` from its current position.
    pub fn new(source: Source) -> Self {
        Self {
            source,
            buf: [0; 1024],
            start: 0,
            end: 0,
            eof: false,
            line_no: 0,
        }
    }

    /// 1-based number of the line last returned.
    pub fn line_no(&self) -> u32 {
        self.line_no
    }

    /// Starts again from the first line.
    pub fn rewind(&mut self) -> Result<(), ReplayError> {
        self.source.rewind()?;
        self.start = 0;
        self.end = 0;
        self.eof = false;
        self.line_no = 0;
        Ok(())
    }

    /// Copies the next line (without `\r\n`) into `line`; `None` at end of input.
    pub fn next_line<'l>(
        &mut self,
        line: &'l mut [u8; LINE_MAX],
    ) -> Result<Option<&'l [u8]>, ReplayError> {
        loop {
            let pending = self.buf.get(self.start..self.end).unwrap_or(&[]);
            let newline = pending.iter().position(|&b| b == b'\n');
            if newline.is_some() || (self.eof && !pending.is_empty()) {
                let len = newline.unwrap_or(pending.len());
                let mut text = pending.get(..len).unwrap_or(&[]);
                if let Some(stripped) = text.strip_suffix(b"\r") {
                    text = stripped;
                }
                self.start += newline.map_or(len, |n| n + 1);
                self.line_no = self.line_no.saturating_add(1);
                let dst = line
                    .get_mut(..text.len())
                    .ok_or(ReplayError::LineTooLong(self.line_no))?;
                dst.copy_from_slice(text);
                return Ok(Some(&*dst));
            }
            if self.eof {
                return Ok(None);
            }
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
            if self.end == self.buf.len() {
                return Err(ReplayError::LineTooLong(self.line_no.saturating_add(1)));
            }
            let free = self.buf.get_mut(self.end..).unwrap_or(&mut []);
            let n = self.source.read(free)?;
            if n == 0 {
                self.eof = true;
            }
            self.end += n;
        }
    }
}

/// One parsed line: `Ok(None)` for a blank line, a `candump -d` drop count (not a frame: the
/// recording lost frames there, which host replay reports) or `candump -e`'s explanation of an
/// error frame (a line that starts with a tab), `Err(Unsupported)` for a frame the node does
/// not use (remote, CAN FD, error).
fn parse_line(text: &[u8]) -> Result<Option<TimedFrame>, LineError> {
    let text = core::str::from_utf8(text).map_err(|_| LineError::Syntax(CandumpError::BadHex))?;
    if text.trim().is_empty()
        || catmodel::can::candump::dropped_frames(text).is_some()
        || catmodel::can::candump::is_error_detail(text)
    {
        return Ok(None);
    }
    candump::parse(text).map(Some)
}

/// What a pass over the input found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InputSummary {
    /// Timestamp of the first frame, us.
    pub first_t_us: u64,
    /// Latest timestamp of any frame, us.
    pub last_t_us: u64,
    /// Frames the node will be given.
    pub frames: u32,
    /// Remote / CAN FD frames that are skipped.
    pub unsupported: u32,
}

/// Checks every line and finds the time span, then rewinds the reader for the replay.
pub fn scan(reader: &mut LineReader) -> Result<InputSummary, ReplayError> {
    let mut line = [0u8; LINE_MAX];
    let mut summary: Option<InputSummary> = None;
    let mut unsupported = 0u32;
    while let Some(text) = reader.next_line(&mut line)? {
        match parse_line(text) {
            Ok(None) => {}
            Ok(Some(frame)) => {
                let s = summary.get_or_insert(InputSummary {
                    first_t_us: frame.t_us,
                    last_t_us: frame.t_us,
                    frames: 0,
                    unsupported: 0,
                });
                s.last_t_us = s.last_t_us.max(frame.t_us);
                s.frames = s.frames.saturating_add(1);
            }
            Err(LineError::Unsupported) => unsupported = unsupported.saturating_add(1),
            Err(LineError::Syntax(error)) => {
                return Err(ReplayError::Syntax(reader.line_no(), error))
            }
        }
    }
    reader.rewind()?;
    let mut summary = summary.ok_or(ReplayError::Empty)?;
    summary.unsupported = unsupported;
    Ok(summary)
}

/// The receive side of the replay bus.
pub struct ReplayBus {
    reader: LineReader,
    line: [u8; LINE_MAX],
    /// The input's time base on the embassy clock.
    clock: ReplayClock,
}

impl ReplayBus {
    /// Replays `reader` (rewound) on `clock`.
    pub fn new(reader: LineReader, clock: ReplayClock) -> Self {
        Self {
            reader,
            line: [0; LINE_MAX],
            clock,
        }
    }
}

impl BusReceiver for ReplayBus {
    async fn receive(&mut self) -> Result<TimedFrame, RxError> {
        loop {
            let frame = match self.reader.next_line(&mut self.line) {
                Ok(None) => return Err(RxError::EndOfInput),
                // The input was checked by `scan`; a host file that changed since is cut short.
                Err(_) => return Err(RxError::EndOfInput),
                Ok(Some(text)) => match parse_line(text) {
                    Ok(None) => continue,
                    Ok(Some(frame)) => frame,
                    Err(_) => return Err(RxError::Unsupported),
                },
            };
            let release_us = self.clock.release_instant_us(frame.t_us);
            if Instant::now().as_micros() < release_us {
                Timer::at(Instant::from_micros(release_us)).await;
            }
            return Ok(frame);
        }
    }
}

/// The transmit side: candump lines (`can0`, stamped with the tick's time) into a host file,
/// buffered and flushed whenever the transmit queue runs empty.
pub struct TxLog {
    file: semihosting::fs::File,
    buf: heapless::Vec<u8, 2048>,
    line: heapless::String<LINE_CAP>,
    failed: bool,
}

impl TxLog {
    /// Writes to `file` (created, truncated).
    pub fn new(file: semihosting::fs::File) -> Self {
        Self {
            file,
            buf: heapless::Vec::new(),
            line: heapless::String::new(),
            failed: false,
        }
    }

    /// Whether any write to the host file failed.
    pub fn failed(&self) -> bool {
        self.failed
    }

    fn flush(&mut self) {
        if !self.buf.is_empty() && self.file.write_all(&self.buf).is_err() {
            self.failed = true;
        }
        self.buf.clear();
    }
}

impl BusTransmitter for TxLog {
    async fn transmit(&mut self, frame: &TimedFrame) -> Result<(), ()> {
        candump::format(frame, "can0", &mut self.line);
        if self.buf.capacity() - self.buf.len() < self.line.len() {
            self.flush();
        }
        self.buf
            .extend_from_slice(self.line.as_bytes())
            .map_err(|_| ())?;
        if self.failed {
            return Err(());
        }
        Ok(())
    }

    fn idle(&mut self) {
        self.flush();
    }
}
