//! `motorbench completions SHELL` and `motorbench man [DIR]`: shell
//! completion scripts and man pages generated from the clap definitions,
//! so they never drift from the flags the binary accepts.
//!
//! The generators take the [`clap::Command`] built from `src/main.rs`'s
//! parser (the library does not know the binary's argument types).

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use clap_complete::Shell;

use super::Failure;

/// Arguments of `motorbench completions`.
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// The shell to write the completion script for (bash, zsh, fish,
    /// elvish, powershell). Install it as that shell expects, e.g. for
    /// bash: `motorbench completions bash > ~/.local/share/bash-completion/completions/motorbench`.
    pub shell: Shell,
}

/// Arguments of `motorbench man`.
#[derive(Debug, Args)]
pub struct ManArgs {
    /// Write `motorbench.1` and one page per subcommand
    /// (`motorbench-run.1`, …) into this directory (created if missing).
    /// Without it, `motorbench.1` goes to standard output.
    pub dir: Option<PathBuf>,
}

/// Write the completion script for `args.shell` to standard output.
pub fn completions(args: CompletionsArgs, mut cmd: clap::Command) -> Result<(), Failure> {
    let name = cmd.get_name().to_string();
    let mut out = Vec::new();
    clap_complete::generate(args.shell, &mut cmd, name, &mut out);
    std::io::stdout()
        .write_all(&out)
        .map_err(|e| Failure::runtime(format!("writing the completion script: {e}")))
}

/// Write the man pages: the top page to standard output, or every page
/// into `args.dir`, printing each path written.
pub fn man(args: ManArgs, cmd: clap::Command) -> Result<(), Failure> {
    let cmd = cmd.version(env!("CARGO_PKG_VERSION"));
    match args.dir {
        None => {
            let page = render(&cmd)?;
            std::io::stdout()
                .write_all(&page)
                .map_err(|e| Failure::runtime(format!("writing the man page: {e}")))
        }
        Some(dir) => {
            std::fs::create_dir_all(&dir)
                .map_err(|e| Failure::runtime(format!("creating {}: {e}", dir.display())))?;
            for path in write_pages(&cmd, &dir)? {
                println!("{}", path.display());
            }
            Ok(())
        }
    }
}

/// `cmd`'s page as roff.
fn render(cmd: &clap::Command) -> Result<Vec<u8>, Failure> {
    let mut page = Vec::new();
    clap_mangen::Man::new(cmd.clone())
        .render(&mut page)
        .map_err(|e| Failure::runtime(format!("rendering the man page: {e}")))?;
    Ok(page)
}

/// Write `cmd`'s page and its subcommands' (`motorbench-run.1`, …) into
/// `dir`; the paths written, the top page first.
fn write_pages(cmd: &clap::Command, dir: &Path) -> Result<Vec<PathBuf>, Failure> {
    let top = cmd.get_name().to_string();
    let mut written = Vec::new();
    let mut pages = vec![(top.clone(), cmd.clone())];
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        let name = format!("{top}-{}", sub.get_name());
        let mut page = sub.clone().name(name.clone());
        if let Some(version) = cmd.get_version() {
            page = page.version(version.to_string());
        }
        pages.push((name, page));
    }
    for (name, page_cmd) in pages {
        let path = dir.join(format!("{name}.1"));
        std::fs::write(&path, render(&page_cmd)?)
            .map_err(|e| Failure::runtime(format!("writing {}: {e}", path.display())))?;
        written.push(path);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{CommandFactory, Parser, Subcommand};

    /// A parser shaped like the binary's: a top command with subcommands.
    #[derive(Parser)]
    #[command(name = "tool", about = "A tool.")]
    struct Tool {
        #[command(subcommand)]
        command: Sub,
    }

    #[derive(Subcommand)]
    enum Sub {
        /// Run a thing.
        Run {
            /// How fast.
            #[arg(long)]
            speed: f64,
        },
        /// Read a thing.
        Read,
    }

    #[test]
    fn one_page_per_subcommand_named_for_it() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_pages(&Tool::command().version("2.5"), dir.path()).unwrap();
        let names: Vec<String> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, ["tool.1", "tool-run.1", "tool-read.1"]);
        let run = std::fs::read_to_string(&written[1]).unwrap();
        assert!(run.starts_with(".ie"), "{run}");
        assert!(run.contains(".TH tool-run 1"), "{run}");
        assert!(run.contains("\\-\\-speed"), "{run}");
        assert!(run.contains("How fast"), "{run}");
        assert!(
            run.contains("\"tool-run 2.5\""),
            "the version is on every page: {run}"
        );
    }
}
