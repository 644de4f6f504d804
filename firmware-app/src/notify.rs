//! systemd readiness and watchdog notifications (the `sd_notify(3)` protocol), without libsystemd or a crate.
//!
//! Under a unit with `Type=notify`, systemd passes `$NOTIFY_SOCKET`: the path of a unix datagram socket, or
//! `@name` for one in the abstract namespace. The service sends it datagrams of newline-separated `KEY=VALUE`
//! assignments: `READY=1` once start-up is done (for `supine run`: after the init phase, when tracking starts),
//! `WATCHDOG=1` at least every `$WATCHDOG_USEC` microseconds while it is healthy (systemd restarts it otherwise, see
//! `WatchdogSec=` in cross/debian/supine.service), `STOPPING=1` when it shuts down, `STATUS=…` free text for
//! `systemctl status`. Outside systemd `$NOTIFY_SOCKET` is unset and [`Notifier::from_env`] returns `None`.
//!
//! The socket is opened once at start-up; [`Notifier::watchdog`] then sends a fixed datagram without allocating,
//! so the frame loop can call it (every frame, or every few frames within [`watchdog_interval`] / 2).

use std::ffi::{OsStr, OsString};
use std::io;
use std::os::linux::net::SocketAddrExt;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::Duration;

/// An open connection to the service manager's notification socket.
#[derive(Debug)]
pub struct Notifier {
    socket: UnixDatagram,
    addr: SocketAddr,
}

impl Notifier {
    /// The notifier systemd asked for through `$NOTIFY_SOCKET`, or `None` when not started by systemd with
    /// `Type=notify` (or `NotifyAccess=`). Errors only if the variable is set but the socket cannot be used.
    pub fn from_env() -> io::Result<Option<Self>> {
        Self::from_var(std::env::var_os("NOTIFY_SOCKET"))
    }

    /// [`Self::from_env`] with the variable's value passed in (tests cannot set the environment safely).
    fn from_var(value: Option<OsString>) -> io::Result<Option<Self>> {
        match value {
            Some(v) if !v.is_empty() => Self::connect(&v).map(Some),
            _ => Ok(None),
        }
    }

    /// A notifier sending to `socket`: a filesystem path, or `@name` for the abstract namespace.
    pub fn connect(socket: &OsStr) -> io::Result<Self> {
        let bytes = socket.as_bytes();
        let addr = match bytes.split_first() {
            Some((b'@', name)) => SocketAddr::from_abstract_name(name)?,
            Some((b'/', _)) => SocketAddr::from_pathname(socket)?,
            _ => {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidInput,
                    format!("NOTIFY_SOCKET {socket:?} is neither an absolute path nor an @abstract name"),
                ));
            }
        };
        let socket = UnixDatagram::unbound()?;
        Ok(Self { socket, addr })
    }

    /// Sends one datagram of `KEY=VALUE` lines as they are.
    pub fn send(&self, state: &str) -> io::Result<()> {
        let sent = self.socket.send_to_addr(state.as_bytes(), &self.addr)?;
        if sent != state.len() {
            return Err(io::Error::new(
                io::ErrorKind::WriteZero,
                "notification datagram truncated",
            ));
        }
        Ok(())
    }

    /// Start-up is complete: systemd considers the unit started (`Type=notify`) from now on.
    pub fn ready(&self) -> io::Result<()> {
        self.send("READY=1")
    }

    /// Keep-alive for `WatchdogSec=`. Allocation-free; safe to call from the frame loop.
    pub fn watchdog(&self) -> io::Result<()> {
        self.send("WATCHDOG=1")
    }

    /// The service is shutting down on purpose (not a crash).
    pub fn stopping(&self) -> io::Result<()> {
        self.send("STOPPING=1")
    }

    /// A one-line status for `systemctl status`; cut at the first newline and to 200 bytes (on a char boundary).
    /// Allocation-free: the datagram is assembled on the stack.
    pub fn status(&self, text: &str) -> io::Result<()> {
        const PREFIX: &[u8] = b"STATUS=";
        const MAX_TEXT: usize = 200;
        let line = text.split('\n').next().unwrap_or("");
        let mut end = line.len().min(MAX_TEXT);
        while !line.is_char_boundary(end) {
            end -= 1;
        }
        let mut buf = [0u8; PREFIX.len() + MAX_TEXT];
        buf[..PREFIX.len()].copy_from_slice(PREFIX);
        buf[PREFIX.len()..PREFIX.len() + end].copy_from_slice(&line.as_bytes()[..end]);
        let datagram = &buf[..PREFIX.len() + end];
        let sent = self.socket.send_to_addr(datagram, &self.addr)?;
        if sent != datagram.len() {
            return Err(io::Error::new(
                io::ErrorKind::WriteZero,
                "notification datagram truncated",
            ));
        }
        Ok(())
    }
}

/// The watchdog interval systemd expects keep-alives within (`WatchdogSec=`), if it set one for this process.
/// Send [`Notifier::watchdog`] at least twice per interval.
pub fn watchdog_interval() -> Option<Duration> {
    let usec = std::env::var("WATCHDOG_USEC").ok();
    let pid = std::env::var("WATCHDOG_PID").ok();
    parse_watchdog(usec.as_deref(), pid.as_deref(), std::process::id())
}

/// `$WATCHDOG_USEC` as a duration, if set, positive, and meant for `my_pid` (`$WATCHDOG_PID` unset or equal).
fn parse_watchdog(usec: Option<&str>, pid: Option<&str>, my_pid: u32) -> Option<Duration> {
    if let Some(pid) = pid
        && pid.trim().parse::<u32>().ok()? != my_pid
    {
        return None;
    }
    match usec?.trim().parse::<u64>().ok()? {
        0 => None,
        us => Some(Duration::from_micros(us)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;
    use std::sync::atomic::{AtomicU32, Ordering};

    /// A fresh socket path in the temp dir, unique per process and call.
    fn socket_path() -> PathBuf {
        static N: AtomicU32 = AtomicU32::new(0);
        let n = N.fetch_add(1, Ordering::Relaxed);
        std::env::temp_dir().join(format!("supine-notify-test-{}-{n}.sock", std::process::id()))
    }

    fn recv(server: &UnixDatagram) -> String {
        server.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        let mut buf = [0u8; 512];
        let n = server.recv(&mut buf).unwrap();
        String::from_utf8(buf[..n].to_vec()).unwrap()
    }

    #[test]
    fn sends_each_notification_as_one_datagram_to_a_path_socket() {
        let path = socket_path();
        let _ = std::fs::remove_file(&path);
        let server = UnixDatagram::bind(&path).unwrap();
        let n = Notifier::from_var(Some(path.clone().into_os_string()))
            .unwrap()
            .expect("socket set");
        n.ready().unwrap();
        n.watchdog().unwrap();
        n.status("tracking\nsecond line is dropped").unwrap();
        n.stopping().unwrap();
        assert_eq!(recv(&server), "READY=1");
        assert_eq!(recv(&server), "WATCHDOG=1");
        assert_eq!(recv(&server), "STATUS=tracking");
        assert_eq!(recv(&server), "STOPPING=1");
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn abstract_namespace_socket() {
        let name = format!("supine-notify-test-abstract-{}", std::process::id());
        let server =
            UnixDatagram::bind_addr(&SocketAddr::from_abstract_name(name.as_bytes()).unwrap()).unwrap();
        let n = Notifier::connect(OsStr::new(&format!("@{name}"))).unwrap();
        n.send("READY=1\nSTATUS=up").unwrap();
        assert_eq!(recv(&server), "READY=1\nSTATUS=up");
    }

    #[test]
    fn status_is_cut_to_200_bytes_on_a_char_boundary() {
        let path = socket_path();
        let server = UnixDatagram::bind(&path).unwrap();
        let n = Notifier::connect(path.as_os_str()).unwrap();
        // 'é' is two bytes: 150 of them are 300 bytes, cut to 100 characters.
        n.status(&"é".repeat(150)).unwrap();
        assert_eq!(recv(&server), format!("STATUS={}", "é".repeat(100)));
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn no_socket_means_no_notifier() {
        assert!(Notifier::from_var(None).unwrap().is_none());
        assert!(Notifier::from_var(Some(OsString::new())).unwrap().is_none());
    }

    #[test]
    fn relative_socket_path_is_an_error_naming_it() {
        let err = Notifier::connect(OsStr::new("relative.sock")).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(err.to_string().contains("relative.sock"), "{err}");
    }

    #[test]
    fn sending_to_a_missing_socket_is_an_error_not_a_panic() {
        let n = Notifier::connect(socket_path().as_os_str()).unwrap();
        assert!(n.ready().is_err());
    }

    #[test]
    fn watchdog_interval_from_the_environment_values() {
        assert_eq!(
            parse_watchdog(Some("2000000"), None, 42),
            Some(Duration::from_secs(2))
        );
        assert_eq!(
            parse_watchdog(Some("500000"), Some("42"), 42),
            Some(Duration::from_millis(500))
        );
        assert_eq!(
            parse_watchdog(Some("500000"), Some("41"), 42),
            None,
            "meant for another process"
        );
        assert_eq!(parse_watchdog(Some("0"), None, 42), None);
        assert_eq!(parse_watchdog(Some("soon"), None, 42), None);
        assert_eq!(parse_watchdog(None, None, 42), None);
    }
}
