//! Progress display for the long-running commands: an `indicatif` bar (or spinner, for work
//! whose size is unknown) that appears only if the work is still running after
//! [`SHOW_AFTER`] and only when stderr is a terminal, so short runs, pipes and CI logs stay
//! clean.
use std::io::IsTerminal;
use std::sync::mpsc::{self, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Work shorter than this shows nothing.
pub const SHOW_AFTER: Duration = Duration::from_secs(1);

/// A progress display; [`Progress::finish`] (or drop) removes it.
pub struct Progress {
    bar: ProgressBar,
    stop: Option<Sender<()>>,
    watcher: Option<JoinHandle<()>>,
}

impl Progress {
    /// A bar over `len` units of work, labelled `msg`.
    pub fn bar(len: u64, msg: &str) -> Self {
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
        if let Ok(style) =
            ProgressStyle::with_template("{msg:>12} [{bar:40}] {percent:>3}% {elapsed} (eta {eta})")
        {
            bar.set_style(style.progress_chars("=> "));
        }
        Self::start(bar, msg)
    }

    /// A spinner for work of unknown size, labelled `msg`.
    pub fn spinner(msg: &str) -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden());
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} {elapsed}") {
            bar.set_style(style);
        }
        Self::start(bar, msg)
    }

    fn start(bar: ProgressBar, msg: &str) -> Self {
        bar.set_message(msg.to_string());
        if !std::io::stderr().is_terminal() {
            return Self {
                bar,
                stop: None,
                watcher: None,
            };
        }
        let (tx, rx) = mpsc::channel::<()>();
        let shown = bar.clone();
        let watcher = std::thread::spawn(move || {
            if let Err(RecvTimeoutError::Timeout) = rx.recv_timeout(SHOW_AFTER) {
                shown.set_draw_target(ProgressDrawTarget::stderr());
                shown.enable_steady_tick(Duration::from_millis(100));
            }
        });
        Self {
            bar,
            stop: Some(tx),
            watcher: Some(watcher),
        }
    }

    /// Counts `n` units done.
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
    }

    /// Changes the label (e.g. the phase of the work).
    pub fn set_message(&self, msg: &str) {
        self.bar.set_message(msg.to_string());
    }

    /// Removes the display.
    pub fn finish(mut self) {
        self.close();
    }

    fn close(&mut self) {
        // Dropping the sender wakes the watcher; once it has returned nothing draws any more.
        self.stop = None;
        if let Some(w) = self.watcher.take() {
            let _ = w.join();
        }
        self.bar.finish_and_clear();
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.close();
    }
}
