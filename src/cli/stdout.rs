//! Standard output for the commands' results. A reader that has gone away
//! (`motorbench run --json | head`) ends the output quietly instead of
//! panicking: by the time a command prints, its test is over, the rig is
//! safe and its files are written. Any other write error is said once on
//! standard error.

use std::io::Write;

/// Write `args` to standard output (see the module docs).
pub(crate) fn write(args: std::fmt::Arguments<'_>) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("motorbench: writing to standard output failed: {e}");
        }
    }
}

/// `print!` through [`write`].
macro_rules! out {
    ($($t:tt)*) => {
        $crate::cli::stdout::write(format_args!($($t)*))
    };
}

/// `println!` through [`write`].
macro_rules! outln {
    () => {
        $crate::cli::stdout::write(format_args!("\n"))
    };
    ($($t:tt)*) => {
        $crate::cli::stdout::write(format_args!("{}\n", format_args!($($t)*)))
    };
}

pub(crate) use {out, outln};
