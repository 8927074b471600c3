//! Output files that appear complete or not at all, even when the process is stopped by a
//! signal.
//!
//! An [`OutputFile`] is written under a hidden temporary name beside its path
//! (`.trajectory.XXXXXX.tum`: the extension kept, for writers that choose the format by it)
//! and renamed into place by [`OutputFile::commit`]; dropped before
//! (an error, a panic), it removes its temporary file. A signal ends a process without running
//! drops, so every temporary file is also listed here while it lives, and
//! [`remove_on_signal`] starts a thread that, on SIGINT, SIGTERM or SIGHUP, removes the listed
//! files and then lets the signal end the process as it would have (exit status 128 + signal
//! in a shell). Nothing is ever written under the final names but by the rename.
//!
//! A path that names a device, a pipe or a socket (`/dev/null`, `/dev/stdout`, a FIFO) is
//! written to directly: a rename would replace it with a regular file.

use anyhow::{Context, Result};
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, OnceLock, PoisonError};
use tempfile::NamedTempFile;

/// The temporary files alive in this process, by registration number.
static LIVE: Mutex<Registry> = Mutex::new(Registry {
    next: 0,
    paths: BTreeMap::new(),
});

#[derive(Debug)]
struct Registry {
    next: u64,
    paths: BTreeMap<u64, PathBuf>,
}

fn live() -> MutexGuard<'static, Registry> {
    LIVE.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A listed temporary file; unlisted when dropped.
#[derive(Debug)]
struct Listed(u64);

impl Drop for Listed {
    fn drop(&mut self) {
        live().paths.remove(&self.0);
    }
}

/// A file written under a temporary name beside `path` and renamed into place when complete.
#[derive(Debug)]
pub struct OutputFile {
    path: PathBuf,
    file: BufWriter<Target>,
    // Declared after `file`, so it is unlisted only once the file is removed or renamed.
    _listed: Option<Listed>,
}

/// Where an [`OutputFile`]'s bytes go.
#[derive(Debug)]
enum Target {
    /// The temporary file renamed into place.
    Temporary(NamedTempFile),
    /// A device, pipe or socket at the path, written to directly.
    Special(std::fs::File),
}

impl Write for Target {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Target::Temporary(f) => f.write(buf),
            Target::Special(f) => f.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Target::Temporary(f) => f.flush(),
            Target::Special(f) => f.flush(),
        }
    }
}

impl Seek for Target {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        match self {
            Target::Temporary(f) => f.seek(pos),
            Target::Special(f) => f.seek(pos),
        }
    }
}

/// Gives `file`, which is to replace `path`, the permission bits of the regular file at `path`
/// (setuid, setgid and sticky bits dropped) and, where the process may, its owner and group:
/// replacing an output keeps who may read it, and never lets more read it (a group the writer
/// cannot give the file to loses its bits). A link at `path` is replaced by a new file (never
/// written through), which gets the permissions of a new file.
fn keep_owner_and_mode(path: &Path, file: &std::fs::File) -> std::io::Result<()> {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let Ok(old) = std::fs::symlink_metadata(path) else {
        return Ok(());
    };
    if !old.is_file() {
        return Ok(());
    }
    // Owner first: changing it may clear permission bits, which are then set.
    let permission_denied = |r: &std::io::Result<()>| matches!(r, Err(e) if e.kind() == std::io::ErrorKind::PermissionDenied);
    let mut mode = old.mode() & 0o777;
    let both = std::os::unix::fs::fchown(file, Some(old.uid()), Some(old.gid()));
    if permission_denied(&both) {
        // Only a privileged process may give a file away; the new file is then the writer's,
        // as an output written in place by another user would be. It keeps the old group
        // where the writer belongs to it; where not, the group's bits are dropped rather
        // than granted to the writer's own group.
        let group = std::os::unix::fs::fchown(file, None, Some(old.gid()));
        if permission_denied(&group) {
            mode &= !0o070;
        } else {
            group?;
        }
    } else {
        both?;
    }
    file.set_permissions(std::fs::Permissions::from_mode(mode))
}

/// True when `path` (its link followed) is a device, a pipe or a socket.
fn is_special(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

impl OutputFile {
    /// Opens the temporary file in `path`'s directory (which must exist: a bad path fails here,
    /// before any work), with the permissions an ordinary new file gets (0644 less the umask),
    /// not tempfile's private 0600, since it becomes the output; where it replaces a regular
    /// file, with that file's permissions and, where the process may, its owner.
    pub fn create(path: &Path) -> Result<Self> {
        if is_special(path) {
            let file = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .with_context(|| format!("cannot write {}", path.display()))?;
            return Ok(Self {
                path: path.to_path_buf(),
                file: BufWriter::new(Target::Special(file)),
                _listed: None,
            });
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let stem = path
            .file_stem()
            .map_or_else(|| "out".into(), |n| n.to_string_lossy());
        let prefix = format!(".{stem}.");
        let suffix = path
            .extension()
            .map(|e| format!(".{}", e.to_string_lossy()))
            .unwrap_or_default();
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(&suffix).permissions({
            use std::os::unix::fs::PermissionsExt;
            std::fs::Permissions::from_mode(0o644)
        });
        // Created and listed under one lock: a signal's removal (which takes the lock) sees
        // either no file or a listed one.
        let mut registry = live();
        let file = builder
            .tempfile_in(dir)
            .with_context(|| format!("cannot write {}", path.display()))?;
        keep_owner_and_mode(path, file.as_file())
            .with_context(|| format!("cannot write {}", path.display()))?;
        let number = registry.next;
        registry.next += 1;
        registry.paths.insert(number, file.path().to_path_buf());
        drop(registry);
        Ok(Self {
            path: path.to_path_buf(),
            file: BufWriter::new(Target::Temporary(file)),
            _listed: Some(Listed(number)),
        })
    }

    /// The final path.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary file's path, for a writer that takes a path rather than a `Write` (a
    /// plotting backend): what it writes there is what [`commit`](Self::commit) renames into
    /// place. It ends in the final path's extension. For a device, pipe or socket, its path.
    #[must_use]
    pub fn temp_path(&self) -> &Path {
        match self.file.get_ref() {
            Target::Temporary(f) => f.path(),
            Target::Special(_) => &self.path,
        }
    }

    /// Flushes the file, syncs its data to disk and renames it to its path (a device, pipe or
    /// socket is only flushed).
    pub fn commit(self) -> Result<()> {
        let Self {
            path,
            file,
            _listed,
        } = self;
        let file = file
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("writing {}", path.display()))?;
        let file = match file {
            Target::Temporary(file) => file,
            Target::Special(_) => return Ok(()),
        };
        file.as_file()
            .sync_data()
            .with_context(|| format!("writing {}", path.display()))?;
        file.persist(&path)
            .map_err(|e| e.error)
            .with_context(|| format!("renaming into {}", path.display()))?;
        Ok(())
    }
}

impl Write for OutputFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.file.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.file.write_all(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

impl Seek for OutputFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.file.seek(pos)
    }
}

/// An output directory made for a run: removed again when dropped before [`keep`](Self::keep)
/// if this created it and it is still empty, so a run that fails leaves no empty directory
/// behind. A directory that existed before is never removed.
#[derive(Debug)]
pub struct CreatedDir {
    path: PathBuf,
    created: bool,
}

impl CreatedDir {
    /// Creates `path` (and its parents) if it does not exist.
    pub fn create(path: &Path) -> Result<Self> {
        let created = !path.exists();
        std::fs::create_dir_all(path).with_context(|| format!("creating {}", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            created,
        })
    }

    /// The run succeeded: the directory stays.
    pub fn keep(mut self) {
        self.created = false;
    }
}

impl Drop for CreatedDir {
    fn drop(&mut self) {
        if self.created {
            // Fails, as it should, when the directory holds anything.
            let _ = std::fs::remove_dir(&self.path);
        }
    }
}

/// Refuses outputs that are the input file itself (the same file, through any path, link or
/// hard link): an output is renamed into place when complete, which would replace the log
/// being read with, say, the bag converted from it.
pub fn refuse_to_overwrite(input: &Path, outputs: &[&Path]) -> Result<()> {
    use std::os::unix::fs::MetadataExt;
    let Ok(source) = std::fs::metadata(input) else {
        return Ok(());
    };
    for out in outputs {
        if let Ok(m) = std::fs::metadata(out)
            && m.dev() == source.dev()
            && m.ino() == source.ino()
        {
            anyhow::bail!(
                "{} is the input {}: refusing to overwrite it",
                out.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Writes a whole file under a temporary name beside `path` and renames it into place.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut file = OutputFile::create(path)?;
    file.write_all(bytes)
        .with_context(|| format!("writing {}", path.display()))?;
    file.commit()
}

/// Starts (once per process) the thread that removes every live [`OutputFile`]'s temporary
/// file when SIGINT, SIGTERM or SIGHUP arrives, then ends the process by that signal's default
/// action. Call it at the start of a command that writes outputs; not in a process whose
/// SIGINT and SIGTERM something else handles (an iceoryx2 node stops its loops on them and
/// exits cleanly, removing its temporary files through their drops): there, call
/// [`remove_on_hangup`]. A signal the process inherited as ignored (`nohup`, a shell's
/// background job) stays ignored.
pub fn remove_on_signal() -> Result<()> {
    use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
    watch(&[SIGINT, SIGTERM, SIGHUP])
}

/// [`remove_on_signal`] for SIGHUP alone, which iceoryx2 does not catch.
pub fn remove_on_hangup() -> Result<()> {
    watch(&[signal_hook::consts::SIGHUP])
}

fn watch(signals: &[i32]) -> Result<()> {
    static STARTED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    STARTED
        .get_or_init(|| {
            let caught: Vec<i32> = signals.iter().copied().filter(|s| !ignored(*s)).collect();
            start_signal_thread(&caught).map_err(|e| e.to_string())
        })
        .clone()
        .map_err(|e| anyhow::anyhow!("cannot watch for signals: {e}"))
}

/// Whether this process inherited `signal` as ignored (Linux: the `SigIgn` mask of
/// `/proc/self/status`; elsewhere none is taken for ignored). Catching it would undo `nohup`.
fn ignored(signal: i32) -> bool {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else {
        return false;
    };
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigIgn:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| (1..=64).contains(&signal) && mask & (1 << (signal - 1)) != 0)
}

fn start_signal_thread(caught: &[i32]) -> std::io::Result<()> {
    if caught.is_empty() {
        return Ok(());
    }
    let mut signals = signal_hook::iterator::Signals::new(caught)?;
    std::thread::Builder::new()
        .name("qicp-output-signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                // Held until the process ends: no new temporary file can appear meanwhile.
                let registry = live();
                remove_all(&registry);
                // Ends the process as the signal would have; the exit is a fallback only.
                let _ = signal_hook::low_level::emulate_default_handler(signal);
                std::process::exit(128 + signal);
            }
        })?;
    Ok(())
}

fn remove_all(registry: &Registry) {
    for path in registry.paths.values() {
        // Already renamed or removed: nothing to do.
        let _ = std::fs::remove_file(path);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_file_written_through_the_temporary_path_is_what_commit_puts_in_place() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("map_q-wsm.png");
        let out = OutputFile::create(&path).expect("created");
        assert_eq!(
            out.temp_path().extension().and_then(|e| e.to_str()),
            Some("png")
        );
        // As a plotting backend does: its own file at that path.
        std::fs::write(out.temp_path(), b"picture").expect("written by path");
        assert!(!path.exists());
        out.commit().expect("committed");
        assert_eq!(std::fs::read(&path).expect("read"), b"picture");
        assert!(hidden_files(dir.path()).is_empty());
    }

    use super::*;

    fn hidden_files(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .expect("dir")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect()
    }

    #[test]
    fn an_output_file_appears_only_when_committed_and_is_unlisted_after() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("trajectory.tum");
        let mut out = OutputFile::create(&path).expect("created");
        let temp = out.temp_path().to_path_buf();
        assert!(live().paths.values().any(|p| *p == temp));
        out.write_all(b"0 0 0 0 0 0 0 1\n").expect("written");
        assert!(!path.exists());
        assert_eq!(hidden_files(dir.path()).len(), 1);
        let name = &hidden_files(dir.path())[0];
        assert!(
            name.starts_with(".trajectory.") && name.ends_with(".tum"),
            "{name}"
        );
        out.commit().expect("committed");
        assert_eq!(
            std::fs::read_to_string(&path).expect("read"),
            "0 0 0 0 0 0 0 1\n"
        );
        assert!(hidden_files(dir.path()).is_empty());
        assert!(!live().paths.values().any(|p| *p == temp));
    }

    #[test]
    fn a_dropped_output_file_leaves_nothing() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("matches.csv");
        let mut out = OutputFile::create(&path).expect("created");
        out.write_all(b"partial").expect("written");
        drop(out);
        assert!(!path.exists());
        assert!(hidden_files(dir.path()).is_empty());
    }

    #[test]
    fn the_signal_removal_removes_live_temporary_files_and_nothing_committed() {
        let dir = tempfile::tempdir().expect("dir");
        let kept = OutputFile::create(&dir.path().join("a.tum")).expect("a");
        let committed = OutputFile::create(&dir.path().join("b.tum")).expect("b");
        // What the signal thread would find listed (a registry of their own: the process's
        // holds the files of tests running beside this one).
        let registry = Registry {
            next: 2,
            paths: [kept.temp_path(), committed.temp_path()]
                .into_iter()
                .enumerate()
                .map(|(i, p)| (i as u64, p.to_path_buf()))
                .collect(),
        };
        committed.commit().expect("b committed");
        remove_all(&registry);
        assert!(hidden_files(dir.path()).is_empty());
        assert!(dir.path().join("b.tum").exists());
        drop(kept);
    }

    #[test]
    fn a_pipe_at_the_path_is_written_to_not_replaced() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().expect("dir");
        let fifo = dir.path().join("poses.tum");
        let made = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo runs");
        assert!(made.success());
        // And through a link to it, as /dev/stdout links to the process's output.
        let link = dir.path().join("link.tum");
        std::os::unix::fs::symlink(&fifo, &link).expect("link");
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read_to_string(fifo).expect("read"))
        };
        let mut out = OutputFile::create(&link).expect("opened");
        out.write_all(b"0 1 2 0 0 0 0 1\n").expect("written");
        out.commit().expect("committed");
        // Checked before waiting for the reader, which a rename would leave waiting.
        assert!(std::fs::symlink_metadata(&link).expect("link").is_symlink());
        assert!(
            std::fs::metadata(&fifo)
                .expect("still there")
                .file_type()
                .is_fifo()
        );
        assert_eq!(reader.join().expect("reader"), "0 1 2 0 0 0 0 1\n");
    }

    #[test]
    fn a_link_to_a_regular_file_is_replaced_not_written_through() {
        let dir = tempfile::tempdir().expect("dir");
        let other = dir.path().join("other.txt");
        std::fs::write(&other, "someone else's").expect("written");
        let link = dir.path().join("trajectory.tum");
        std::os::unix::fs::symlink(&other, &link).expect("link");
        write_atomic(&link, b"ours").expect("written");
        assert_eq!(
            std::fs::read_to_string(&other).expect("read"),
            "someone else's"
        );
        assert!(!std::fs::symlink_metadata(&link).expect("file").is_symlink());
        assert_eq!(std::fs::read_to_string(&link).expect("read"), "ours");
    }

    #[test]
    fn a_replaced_output_keeps_its_permissions_and_owner() {
        use std::os::unix::fs::{MetadataExt, PermissionsExt};
        let dir = tempfile::tempdir().expect("dir");
        for mode in [0o600, 0o640, 0o444, 0o755] {
            let path = dir.path().join("trajectory.tum");
            std::fs::write(&path, "old").expect("written");
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).expect("mode");
            write_atomic(&path, b"new").expect("written");
            let meta = std::fs::metadata(&path).expect("file");
            assert_eq!(meta.mode() & 0o7777, mode, "{mode:o}");
            assert_eq!(std::fs::read_to_string(&path).expect("read"), "new");
            std::fs::remove_file(&path).expect("removed");
        }
        // A fresh output gets an ordinary new file's permissions (0644 less the umask), not
        // tempfile's 0600: those of a file the standard library creates beside it.
        let fresh = dir.path().join("fresh.tum");
        write_atomic(&fresh, b"new").expect("written");
        let ordinary = dir.path().join("ordinary.tum");
        std::fs::write(&ordinary, "new").expect("written");
        let mode = |p: &Path| std::fs::metadata(p).expect("file").mode() & 0o777;
        assert_eq!(mode(&fresh), mode(&ordinary) & 0o644, "{:o}", mode(&fresh));
        // The owner is kept where the process may give files away (root).
        let path = dir.path().join("summary.json");
        std::fs::write(&path, "old").expect("written");
        if std::os::unix::fs::chown(&path, Some(4321), Some(4321)).is_ok() {
            write_atomic(&path, b"new").expect("written");
            let meta = std::fs::metadata(&path).expect("file");
            assert_eq!((meta.uid(), meta.gid()), (4321, 4321));
        }
    }

    #[test]
    fn an_output_in_a_missing_directory_fails_at_creation_naming_it() {
        let dir = tempfile::tempdir().expect("dir");
        let path = dir.path().join("no-such-dir").join("summary.json");
        let error = OutputFile::create(&path).expect_err("refused");
        assert!(format!("{error:#}").contains("summary.json"), "{error:#}");
    }
}
