//! The paths a command reads and writes, checked before it reads anything: an output that is
//! one of the command's own inputs (`replay in.can.log --out in.can.log` wrote the predictions
//! over the drive it was replaying, with exit status 0), two outputs given the same path, an
//! output file whose directory does not exist (it was created with all its parents, silently:
//! a typo'd path left files somewhere unexpected), an output directory that is a file
//! (`identify --report FILE` failed only after the whole identification, naming no path).
//!
//! One place for every command: each one lists its inputs and outputs in a [`Paths`] and calls
//! [`Paths::check`] first.
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};

/// What an output path names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// A file, written over if it exists; its directory must exist.
    File,
    /// A directory the command writes into, created (with its parents) if it does not exist,
    /// as the README documents for `--out DIR`, `--plots DIR` and `--report DIR`.
    Dir,
}

/// The files a command reads and the files and directories it writes, each with the argument
/// that named it (`--out`, `LOG`), in the order given.
#[derive(Clone, Debug, Default)]
pub struct Paths {
    inputs: Vec<(PathBuf, String)>,
    outputs: Vec<(PathBuf, String, Kind)>,
}

impl Paths {
    /// No paths.
    pub fn new() -> Self {
        Self::default()
    }

    /// A file the command reads, named by `arg` (`LOG`, `--truth`).
    pub fn input(mut self, path: &Path, arg: &str) -> Self {
        self.inputs.push((path.to_path_buf(), arg.to_string()));
        self
    }

    /// Files the command reads, all named by `arg`.
    pub fn inputs<'a>(mut self, paths: impl IntoIterator<Item = &'a PathBuf>, arg: &str) -> Self {
        for p in paths {
            self = self.input(p, arg);
        }
        self
    }

    /// An optional file the command reads.
    pub fn input_opt(self, path: Option<&Path>, arg: &str) -> Self {
        match path {
            Some(p) => self.input(p, arg),
            None => self,
        }
    }

    /// A file or directory the command writes, named by `arg` (`--out`).
    pub fn output(mut self, path: &Path, arg: &str, kind: Kind) -> Self {
        self.outputs
            .push((path.to_path_buf(), arg.to_string(), kind));
        self
    }

    /// An optional file or directory the command writes.
    pub fn output_opt(self, path: Option<&Path>, arg: &str, kind: Kind) -> Self {
        match path {
            Some(p) => self.output(p, arg, kind),
            None => self,
        }
    }

    /// Refuses, naming the path and the argument, before anything is read or written:
    /// - an output that is the same file as an input (the same path after symbolic links and
    ///   `..`, or the same device and inode: a hard link);
    /// - two outputs that are the same path;
    /// - an output file that is a directory, or whose directory does not exist (unless another
    ///   output of the command is that directory, to be created);
    /// - an output directory that exists and is not a directory.
    ///
    /// - a file given twice to one argument (the same file, or a copy of it: the same length,
    ///   first and last 64 KiB), whose frames or rows would count twice: a black-box probe's
    ///   parked log given twice to `receiver-error` read as a receiver at 200 Hz, a session's
    ///   frames given twice to `identify-steering` as twice its commands.
    ///
    /// An output that exists and is neither a regular file nor a directory (`/dev/null`, a
    /// pipe) is written in place and may be given more than once.
    pub fn check(&self) -> Result<()> {
        for (i, (path, arg)) in self.inputs.iter().enumerate() {
            let twice = self.inputs[..i]
                .iter()
                .find(|(p, a)| a == arg && (same(p, path) || copies(p, path)));
            if let Some((first, _)) = twice {
                bail!(
                    "{}: the same log as {} ({arg}): its contents would count twice; give it once",
                    path.display(),
                    first.display()
                );
            }
        }
        for (path, arg, kind) in &self.outputs {
            let meta = std::fs::metadata(path).ok();
            match kind {
                Kind::File => {
                    if meta.as_ref().is_some_and(|m| m.is_dir()) {
                        bail!(
                            "{}: is a directory ({arg} names the file to write)",
                            path.display()
                        );
                    }
                    let dir = parent(path);
                    if !std::fs::metadata(&dir).is_ok_and(|m| m.is_dir()) && !self.creates_dir(&dir)
                    {
                        let why = if dir.exists() {
                            "is not a directory"
                        } else {
                            "does not exist (create it first)"
                        };
                        bail!(
                            "{}: the directory {} {why}; nothing written ({arg})",
                            path.display(),
                            dir.display()
                        );
                    }
                }
                Kind::Dir => {
                    if meta.as_ref().is_some_and(|m| !m.is_dir()) {
                        bail!(
                            "{}: exists and is not a directory ({arg} names a directory to \
                             write into)",
                            path.display()
                        );
                    }
                }
            }
        }
        for (i, (out, arg, _)) in self.outputs.iter().enumerate() {
            if is_special(out) {
                continue;
            }
            if let Some((_, input_arg)) = self.inputs.iter().find(|(p, _)| same(p, out)) {
                bail!(
                    "{}: is also an input ({arg} and {input_arg}): refused before anything was \
                     read, so the input is untouched; give {arg} another path",
                    out.display()
                );
            }
            if let Some((_, other, _)) = self.outputs[..i].iter().find(|(p, _, _)| same(p, out)) {
                bail!(
                    "{}: given as two outputs ({other} and {arg}): one would overwrite the \
                     other; give them different paths",
                    out.display()
                );
            }
        }
        Ok(())
    }

    /// One of the outputs is the directory `dir`, created by the command.
    fn creates_dir(&self, dir: &Path) -> bool {
        self.outputs
            .iter()
            .any(|(p, _, kind)| *kind == Kind::Dir && resolve(p) == resolve(dir))
    }
}

/// The directory a file path is in (`.` for a bare name).
fn parent(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// An existing path that is neither a regular file nor a directory (`/dev/null`, a pipe).
fn is_special(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// `a` and `b` are the same file: the same device and inode when both exist (Unix), else the
/// same absolute path with the symbolic links of its existing part resolved.
fn same(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) {
            return ma.dev() == mb.dev() && ma.ino() == mb.ino();
        }
    }
    resolve(a) == resolve(b)
}

/// `a` and `b` are regular files of the same length, not empty, whose first and last 64 KiB
/// are the same: one is a copy of the other (two recordings do not share both ends).
fn copies(a: &Path, b: &Path) -> bool {
    use std::io::{Read, Seek, SeekFrom};
    const SPAN: u64 = 64 * 1024;
    let len = |p: &Path| {
        std::fs::metadata(p)
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.len())
    };
    let (Some(la), Some(lb)) = (len(a), len(b)) else {
        return false;
    };
    if la != lb || la == 0 {
        return false;
    }
    let ends = |p: &Path| -> Option<Vec<u8>> {
        let mut f = std::fs::File::open(p).ok()?;
        let mut head = vec![0; SPAN.min(la) as usize];
        f.read_exact(&mut head).ok()?;
        let mut tail = vec![0; SPAN.min(la) as usize];
        f.seek(SeekFrom::Start(la - tail.len() as u64)).ok()?;
        f.read_exact(&mut tail).ok()?;
        head.extend(tail);
        Some(head)
    };
    matches!((ends(a), ends(b)), (Some(x), Some(y)) if x == y)
}

/// The absolute form of `path`: its longest existing ancestor canonicalized (symbolic links
/// and `..` resolved), the rest appended as given.
fn resolve(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut rest = Vec::new();
    let mut head = absolute.as_path();
    loop {
        if let Ok(c) = std::fs::canonicalize(head) {
            let mut out = c;
            for part in rest.iter().rev() {
                out.push(part);
            }
            return out;
        }
        match (head.parent(), head.file_name()) {
            (Some(p), Some(name)) => {
                rest.push(name.to_os_string());
                head = p;
            }
            _ => return absolute,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("catmodel-outputs-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn an_output_that_is_an_input_is_refused_by_any_spelling() {
        let d = dir();
        let input = d.join("in.can.log");
        std::fs::write(&input, "x").unwrap();
        let spelled = d.join("sub/../in.can.log");
        std::fs::create_dir_all(d.join("sub")).unwrap();
        for out in [input.clone(), spelled] {
            let err = Paths::new()
                .input(&input, "LOG")
                .output(&out, "--out", Kind::File)
                .check()
                .unwrap_err()
                .to_string();
            assert!(err.contains("is also an input (--out and LOG)"), "{err}");
        }
        #[cfg(unix)]
        {
            let link = d.join("hard.log");
            let _ = std::fs::remove_file(&link);
            std::fs::hard_link(&input, &link).unwrap();
            assert!(Paths::new()
                .input(&input, "LOG")
                .output(&link, "--out", Kind::File)
                .check()
                .is_err());
        }
        assert!(Paths::new()
            .input(&input, "LOG")
            .output(&d.join("p.csv"), "--out", Kind::File)
            .check()
            .is_ok());
    }

    #[test]
    fn a_log_given_twice_to_one_argument_is_refused_and_a_copy_too() {
        let d = dir();
        let a = d.join("a.can.log");
        let b = d.join("b.can.log");
        let copy = d.join("copy.can.log");
        std::fs::write(&a, "(1.000000) can0 100#00\n(1.020000) can0 100#01\n").unwrap();
        std::fs::write(&b, "(1.000000) can0 100#00\n(1.020000) can0 100#02\n").unwrap();
        std::fs::copy(&a, &copy).unwrap();
        for twice in [a.clone(), d.join("sub/../a.can.log"), copy] {
            std::fs::create_dir_all(d.join("sub")).unwrap();
            let err = Paths::new()
                .inputs([&a, &b, &twice], "LOGS")
                .check()
                .unwrap_err()
                .to_string();
            assert!(
                err.contains("the same log as") && err.contains("(LOGS)"),
                "{err}"
            );
        }
        // Two logs that differ, and one log given to two arguments (training and validation).
        assert!(Paths::new().inputs([&a, &b], "LOGS").check().is_ok());
        assert!(Paths::new()
            .input(&a, "LOGS")
            .input(&a, "--validate")
            .check()
            .is_ok());
    }

    #[test]
    fn two_outputs_missing_directories_and_files_as_directories_are_refused() {
        let d = dir();
        let p = d.join("new.csv");
        let err = Paths::new()
            .output(&p, "--out", Kind::File)
            .output(&p, "--tx-out", Kind::File)
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("two outputs (--out and --tx-out)"), "{err}");
        let missing = d.join("no/such/p.csv");
        let err = Paths::new()
            .output(&missing, "--out", Kind::File)
            .check()
            .unwrap_err()
            .to_string();
        assert!(err.contains("no/such does not exist"), "{err}");
        assert!(!d.join("no").exists());
        // A file inside an output directory the command creates.
        assert!(Paths::new()
            .output(&d.join("plots"), "--plots", Kind::Dir)
            .output(&d.join("plots/eval.json"), "--json", Kind::File)
            .check()
            .is_ok());
        let file = d.join("afile");
        std::fs::write(&file, "").unwrap();
        let err = Paths::new()
            .output(&file, "--report", Kind::Dir)
            .check()
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("afile: exists and is not a directory"),
            "{err}"
        );
        // /dev/null is written in place, as often as it is given.
        #[cfg(unix)]
        assert!(Paths::new()
            .output(Path::new("/dev/null"), "--out", Kind::File)
            .output(Path::new("/dev/null"), "--tx-out", Kind::File)
            .check()
            .is_ok());
    }
}
