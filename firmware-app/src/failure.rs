//! How a command fails: bad usage (exit 2) or a runtime failure (exit 1), with a message naming what was wrong.

use std::fmt;

/// A command's failure; `main` prints it and maps it to the exit code of the CLI contract.
#[derive(Debug)]
pub enum Failure {
    /// The user asked for something malformed (bad argument, unknown format, bad config value): exit code 2.
    Usage(String),
    /// The work itself failed (device missing, file corrupt, link down): exit code 1.
    Runtime(anyhow::Error),
    /// stdout is a pipe whose reader went away (`| head`): end quietly with 141, the status of a SIGPIPE death.
    BrokenPipe,
}

impl Failure {
    /// A usage failure with this message.
    pub fn usage(msg: impl Into<String>) -> Self {
        Failure::Usage(msg.into())
    }

    /// The process exit code for this failure.
    pub fn exit_code(&self) -> u8 {
        match self {
            Failure::Usage(_) => 2,
            Failure::Runtime(_) => 1,
            Failure::BrokenPipe => 141,
        }
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Failure::Usage(msg) => write!(f, "{msg}"),
            // `{:#}` prints the whole context chain: "opening /dev/ttyUSB0: No such file or directory".
            Failure::Runtime(err) => write!(f, "{err:#}"),
            Failure::BrokenPipe => write!(f, "stdout closed"),
        }
    }
}

impl From<anyhow::Error> for Failure {
    fn from(err: anyhow::Error) -> Self {
        Failure::Runtime(err)
    }
}

impl From<std::io::Error> for Failure {
    fn from(err: std::io::Error) -> Self {
        Failure::Runtime(err.into())
    }
}
