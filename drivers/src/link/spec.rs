//! Parsing the link strings of the CLI contract: `stdout`, `serial:PATH[@BAUD]`, `slcan:PATH[@BAUD]`, `can:IFACE`,
//! `file:PATH`. Parsed once at start-up; errors name the bad part of the string.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

use super::error::{LinkError, LinkErrorKind};

/// Baud rate of `serial:` and `slcan:` when the spec gives none.
pub const DEFAULT_BAUD: u32 = 115_200;

/// Longest SocketCAN interface name: `IFNAMSIZ` (16, `linux/if.h`) minus the terminating NUL.
pub const MAX_IFACE_LEN: usize = 15;

/// A parsed link string.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LinkSpec {
    /// Serial frames (postcard + CRC + COBS) written to standard output; send only.
    Stdout,
    /// A serial port (termios, raw 8N1) carrying COBS-framed messages.
    Serial {
        /// Device path, e.g. `/dev/ttyUSB0`.
        path: PathBuf,
        /// Line rate in baud.
        baud: u32,
    },
    /// A Lawicel SLCAN adapter on a serial port, carrying the CAN mapping of the messages.
    Slcan {
        /// Device path, e.g. `/dev/ttyACM0`.
        path: PathBuf,
        /// Line rate of the adapter's serial side in baud (USB adapters ignore it).
        baud: u32,
    },
    /// A SocketCAN interface, e.g. `can0`.
    Can {
        /// Interface name.
        iface: String,
    },
    /// A file: sending writes the serial framing to it (a capture), listening reads such a capture back.
    File {
        /// File path.
        path: PathBuf,
    },
}

impl LinkSpec {
    /// The spec's kind as written before the colon.
    pub fn kind_name(&self) -> &'static str {
        match self {
            LinkSpec::Stdout => "stdout",
            LinkSpec::Serial { .. } => "serial",
            LinkSpec::Slcan { .. } => "slcan",
            LinkSpec::Can { .. } => "can",
            LinkSpec::File { .. } => "file",
        }
    }

    /// Whether this link can receive (everything but `stdout`).
    pub fn can_receive(&self) -> bool {
        !matches!(self, LinkSpec::Stdout)
    }
}

impl fmt::Display for LinkSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkSpec::Stdout => write!(f, "stdout"),
            LinkSpec::Serial { path, baud } => write!(f, "serial:{}@{baud}", path.display()),
            LinkSpec::Slcan { path, baud } => write!(f, "slcan:{}@{baud}", path.display()),
            LinkSpec::Can { iface } => write!(f, "can:{iface}"),
            LinkSpec::File { path } => write!(f, "file:{}", path.display()),
        }
    }
}

const EXPECTED: &str = "expected stdout, serial:PATH[@BAUD], slcan:PATH[@BAUD], can:IFACE or file:PATH";

fn bad(msg: String) -> LinkError {
    LinkError::new(LinkErrorKind::InvalidSpec, msg)
}

fn parse_port(kind: &str, rest: &str, whole: &str) -> Result<(PathBuf, u32), LinkError> {
    let (path, baud) = match rest.rsplit_once('@') {
        Some((path, baud_text)) => {
            let baud = baud_text.parse::<u32>().map_err(|_| {
                bad(format!(
                    "link `{whole}`: baud `{baud_text}` is not a whole number (write {kind}:PATH@115200)"
                ))
            })?;
            if baud == 0 {
                return Err(bad(format!("link `{whole}`: baud must be greater than 0")));
            }
            (path, baud)
        }
        None => (rest, DEFAULT_BAUD),
    };
    if path.is_empty() {
        return Err(bad(format!(
            "link `{whole}`: the device path is empty (write {kind}:/dev/ttyUSB0)"
        )));
    }
    Ok((PathBuf::from(path), baud))
}

impl FromStr for LinkSpec {
    type Err = LinkError;

    fn from_str(s: &str) -> Result<Self, LinkError> {
        let whole = s.trim();
        if whole == "stdout" {
            return Ok(LinkSpec::Stdout);
        }
        let Some((kind, rest)) = whole.split_once(':') else {
            return Err(bad(format!("link `{whole}`: no `KIND:` prefix; {EXPECTED}")));
        };
        match kind {
            "serial" => parse_port(kind, rest, whole).map(|(path, baud)| LinkSpec::Serial { path, baud }),
            "slcan" => parse_port(kind, rest, whole).map(|(path, baud)| LinkSpec::Slcan { path, baud }),
            "can" => {
                if rest.is_empty() {
                    Err(bad(format!(
                        "link `{whole}`: the interface name is empty (write can:can0)"
                    )))
                } else if rest.len() > MAX_IFACE_LEN {
                    Err(bad(format!(
                        "link `{whole}`: interface name `{rest}` is longer than {MAX_IFACE_LEN} bytes (IFNAMSIZ)"
                    )))
                } else if rest
                    .bytes()
                    .any(|b| b == b'/' || b == 0 || b.is_ascii_whitespace())
                {
                    Err(bad(format!(
                        "link `{whole}`: interface name `{rest}` contains '/', NUL or whitespace"
                    )))
                } else {
                    Ok(LinkSpec::Can {
                        iface: rest.to_owned(),
                    })
                }
            }
            "file" => {
                if rest.is_empty() {
                    Err(bad(format!(
                        "link `{whole}`: the file path is empty (write file:capture.cobs)"
                    )))
                } else {
                    Ok(LinkSpec::File {
                        path: PathBuf::from(rest),
                    })
                }
            }
            "stdout" => Err(bad(format!("link `{whole}`: `stdout` takes no argument"))),
            other => Err(bad(format!("link `{whole}`: unknown kind `{other}`; {EXPECTED}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::error::Error;

    fn parse(s: &str) -> Result<LinkSpec, LinkError> {
        s.parse()
    }

    #[test]
    fn parses_every_kind() {
        assert_eq!(parse("stdout").unwrap(), LinkSpec::Stdout);
        assert_eq!(
            parse("serial:/dev/ttyUSB0").unwrap(),
            LinkSpec::Serial {
                path: "/dev/ttyUSB0".into(),
                baud: DEFAULT_BAUD
            }
        );
        assert_eq!(
            parse("serial:/dev/ttyUSB0@921600").unwrap(),
            LinkSpec::Serial {
                path: "/dev/ttyUSB0".into(),
                baud: 921_600
            }
        );
        assert_eq!(
            parse("slcan:/dev/pts/3@123457").unwrap(),
            LinkSpec::Slcan {
                path: "/dev/pts/3".into(),
                baud: 123_457
            }
        );
        assert_eq!(
            parse("can:vcan0").unwrap(),
            LinkSpec::Can {
                iface: "vcan0".into()
            }
        );
        assert_eq!(
            parse("file:out/cap.cobs").unwrap(),
            LinkSpec::File {
                path: "out/cap.cobs".into()
            }
        );
    }

    #[test]
    fn display_round_trips() {
        for s in [
            "stdout",
            "serial:/dev/ttyS1@9600",
            "slcan:/tmp/a@115200",
            "can:can0",
            "file:x.bin",
        ] {
            assert_eq!(parse(s).unwrap().to_string(), s);
            assert_eq!(parse(&parse(s).unwrap().to_string()).unwrap(), parse(s).unwrap());
        }
    }

    #[test]
    fn errors_name_the_bad_part() {
        let cases = [
            ("serial:/dev/ttyUSB0@fast", "`fast`"),
            ("serial:@9600", "path is empty"),
            ("serial:/dev/x@0", "greater than 0"),
            ("can:", "interface name is empty"),
            ("can:averyveryverylongname", "longer than 15"),
            ("tcp:1.2.3.4", "unknown kind `tcp`"),
            ("/dev/ttyUSB0", "no `KIND:` prefix"),
            ("file:", "file path is empty"),
            ("stdout:x", "takes no argument"),
        ];
        for (input, needle) in cases {
            let err = parse(input).unwrap_err();
            assert_eq!(err.kind(), LinkErrorKind::InvalidSpec, "{input}");
            let text = err.to_string();
            assert!(text.contains(needle), "{input}: {text}");
            assert!(
                text.contains(input),
                "{input}: message should quote the spec: {text}"
            );
        }
    }

    #[test]
    fn only_stdout_cannot_receive() {
        assert!(!parse("stdout").unwrap().can_receive());
        assert!(parse("file:x").unwrap().can_receive());
    }
}
