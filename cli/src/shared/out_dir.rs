//! Output folders (`--out DIR`, `--out-dir DIR`): checked before a command
//! does its work, so an unwritable path fails at once and not after a
//! 30 s simulation; and never a mix of an old run's files with the new
//! one's: the files the command writes are removed first, and it says so.

use std::path::Path;

use anyhow::Context;
use tracing::info;

/// A file (or a family of files) a command writes into its output folder.
#[derive(Debug, Clone, Copy)]
pub enum Owned {
    /// One file name.
    File(&'static str),
    /// Every file whose name starts with `prefix` and ends with `suffix`
    /// (e.g. `heatmap_` and `.png`).
    Pattern {
        /// Start of the name.
        prefix: &'static str,
        /// End of the name.
        suffix: &'static str,
    },
}

impl Owned {
    fn matches(&self, name: &str) -> bool {
        match *self {
            Owned::File(f) => name == f,
            Owned::Pattern { prefix, suffix } => {
                name.len() >= prefix.len() + suffix.len()
                    && name.starts_with(prefix)
                    && name.ends_with(suffix)
            }
        }
    }
}

/// Creates `dir` if needed, checks that files can be written in it, and
/// removes the files in it that `owned` names (left by an earlier run).
/// Other files are left alone. Returns how many files were removed.
pub fn prepare(command: &str, dir: &Path, owned: &[Owned]) -> anyhow::Result<usize> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    let probe = dir.join(format!(".dexitac-write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write in the output folder {}", dir.display()))?;
    std::fs::remove_file(&probe).with_context(|| format!("cannot remove {}", probe.display()))?;
    let mut removed = 0;
    let entries =
        std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
    for entry in entries {
        let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let is_file = entry.file_type().is_ok_and(|t| t.is_file());
        if is_file && owned.iter().any(|o| o.matches(name)) {
            std::fs::remove_file(entry.path())
                .with_context(|| format!("cannot remove the old {}", entry.path().display()))?;
            removed += 1;
        }
    }
    if removed > 0 {
        info!(
            "dexitac {command}: removed {removed} file(s) of an earlier run from {}",
            dir.display()
        );
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn removes_only_the_files_the_command_owns() {
        let dir = tempfile::tempdir().unwrap();
        for name in [
            "plot.png",
            "heatmap_00_1.00s_seal.png",
            "notes.txt",
            "heatmap.txt",
        ] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let owned = [
            Owned::File("plot.png"),
            Owned::Pattern {
                prefix: "heatmap_",
                suffix: ".png",
            },
        ];
        assert_eq!(prepare("sim", dir.path(), &owned).unwrap(), 2);
        let mut left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        left.sort();
        assert_eq!(left, ["heatmap.txt", "notes.txt"]);
    }

    #[test]
    fn an_unusable_folder_is_an_error_before_any_work() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a-file");
        std::fs::write(&file, b"x").unwrap();
        // A path below a file cannot be a folder.
        let err = prepare("sim", &file.join("out"), &[]).unwrap_err();
        assert!(format!("{err:#}").contains("cannot create the output folder"));
    }
}
