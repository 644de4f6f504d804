//! The systemd watchdog pacer the frame loop calls once per frame: it sends `WATCHDOG=1` when half of
//! `WatchdogSec=` has passed since the last ping, so a loop that stalls (a hung driver, a deadlock) stops the
//! pings and systemd restarts the service. Outside systemd (no `$NOTIFY_SOCKET`) or without `WatchdogSec=` it does
//! nothing. Per frame: one clock comparison; a ping is one datagram send, allocation-free (see [`crate::notify`]).

// The caller is `supine run` (the tracker issue); until it is wired only the tests use this.
#![allow(dead_code)]

use std::time::{Duration, Instant};

use crate::notify::{self, Notifier};

/// Paces `WATCHDOG=1` keep-alives from the frame loop.
#[derive(Debug)]
pub struct WatchdogPacer {
    notifier: Option<Notifier>,
    /// Ping period: half the watchdog interval systemd set.
    period: Option<Duration>,
    last: Option<Instant>,
    pings: u64,
    errors: u64,
}

impl WatchdogPacer {
    /// From the environment systemd set (`$NOTIFY_SOCKET`, `$WATCHDOG_USEC`, `$WATCHDOG_PID`); a socket that is set
    /// but unusable is logged once and treated as absent (the service runs on without notifications).
    pub fn from_env() -> Self {
        let notifier = match Notifier::from_env() {
            Ok(n) => n,
            Err(e) => {
                tracing::warn!("NOTIFY_SOCKET is set but unusable ({e}); no systemd notifications");
                None
            }
        };
        Self::new(notifier, notify::watchdog_interval())
    }

    /// A pacer sending to `notifier` for a watchdog interval of `watchdog` (`None`: no pings).
    pub fn new(notifier: Option<Notifier>, watchdog: Option<Duration>) -> Self {
        WatchdogPacer {
            notifier,
            period: watchdog.map(|w| w / 2),
            last: None,
            pings: 0,
            errors: 0,
        }
    }

    /// Whether pings are being sent at all.
    pub fn active(&self) -> bool {
        self.notifier.is_some() && self.period.is_some()
    }

    /// Start-up is done (after the init phase): `READY=1`, and the first keep-alive is due one period from now.
    pub fn ready(&mut self, now: Instant) {
        if let Some(n) = &self.notifier
            && let Err(e) = n.ready()
        {
            self.errors += 1;
            tracing::warn!("sd_notify READY=1: {e}");
        }
        self.last = Some(now);
    }

    /// Call once per processed frame: pings when a period has passed since the last; true when it pinged.
    pub fn frame(&mut self, now: Instant) -> bool {
        let (Some(n), Some(period)) = (&self.notifier, self.period) else {
            return false;
        };
        if self
            .last
            .is_some_and(|last| now.saturating_duration_since(last) < period)
        {
            return false;
        }
        self.last = Some(now);
        match n.watchdog() {
            Ok(()) => {
                self.pings += 1;
                true
            }
            Err(e) => {
                // Logged once: the loop must not flood the journal every frame.
                if self.errors == 0 {
                    tracing::warn!("sd_notify WATCHDOG=1: {e}");
                }
                self.errors += 1;
                false
            }
        }
    }

    /// The service is stopping on purpose: `STOPPING=1`.
    pub fn stopping(&mut self) {
        if let Some(n) = &self.notifier
            && n.stopping().is_err()
        {
            self.errors += 1;
        }
    }

    /// Keep-alives sent so far.
    pub fn pings(&self) -> u64 {
        self.pings
    }

    /// Notifications that failed to send.
    pub fn errors(&self) -> u64 {
        self.errors
    }
}

#[cfg(test)]
mod tests {
    use std::os::unix::net::UnixDatagram;

    use super::*;

    fn server() -> (UnixDatagram, std::path::PathBuf) {
        use std::sync::atomic::{AtomicU32, Ordering};
        static N: AtomicU32 = AtomicU32::new(0);
        let path = std::env::temp_dir().join(format!(
            "supine-watchdog-test-{}-{}.sock",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_file(&path);
        let s = UnixDatagram::bind(&path).unwrap();
        s.set_nonblocking(true).unwrap();
        (s, path)
    }

    fn received(s: &UnixDatagram) -> Vec<String> {
        let mut out = Vec::new();
        let mut buf = [0u8; 64];
        while let Ok(n) = s.recv(&mut buf) {
            out.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
        out
    }

    #[test]
    fn pings_once_per_half_interval_whatever_the_frame_rate() {
        let (s, path) = server();
        let n = Notifier::connect(path.as_os_str()).unwrap();
        let mut pacer = WatchdogPacer::new(Some(n), Some(Duration::from_secs(2)));
        assert!(pacer.active());
        let t0 = Instant::now();
        pacer.ready(t0);
        // 30 Hz for 5 s: pings at 1, 2, 3, 4, 5 s.
        let pinged = (1..=150)
            .filter(|i| pacer.frame(t0 + Duration::from_micros(33_334 * i)))
            .count();
        assert_eq!(pinged, 5);
        assert_eq!(pacer.pings(), 5);
        pacer.stopping();
        let got = received(&s);
        assert_eq!(got.first().map(String::as_str), Some("READY=1"));
        assert_eq!(got.iter().filter(|m| *m == "WATCHDOG=1").count(), 5);
        assert_eq!(got.last().map(String::as_str), Some("STOPPING=1"));
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn a_stalled_loop_sends_nothing_until_it_runs_again() {
        let (s, path) = server();
        let mut pacer = WatchdogPacer::new(
            Some(Notifier::connect(path.as_os_str()).unwrap()),
            Some(Duration::from_secs(2)),
        );
        let t0 = Instant::now();
        pacer.ready(t0);
        assert!(!pacer.frame(t0 + Duration::from_millis(500)));
        // No frame for 10 s: no call, no ping (systemd would have restarted us); the next frame pings at once.
        assert!(pacer.frame(t0 + Duration::from_secs(10)));
        assert_eq!(received(&s), ["READY=1", "WATCHDOG=1"]);
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn without_systemd_it_does_nothing() {
        let mut pacer = WatchdogPacer::new(None, Some(Duration::from_secs(2)));
        assert!(!pacer.active());
        pacer.ready(Instant::now());
        assert!(!pacer.frame(Instant::now() + Duration::from_secs(5)));
        let (_s, path) = server();
        let mut no_interval = WatchdogPacer::new(Some(Notifier::connect(path.as_os_str()).unwrap()), None);
        assert!(!no_interval.frame(Instant::now()));
        std::fs::remove_file(&path).unwrap();
    }

    #[test]
    fn a_missing_socket_counts_errors_and_never_panics() {
        let path = std::env::temp_dir().join(format!("supine-watchdog-missing-{}.sock", std::process::id()));
        let mut pacer = WatchdogPacer::new(
            Some(Notifier::connect(path.as_os_str()).unwrap()),
            Some(Duration::from_millis(10)),
        );
        let t0 = Instant::now();
        pacer.ready(t0);
        for i in 1..=5 {
            assert!(!pacer.frame(t0 + Duration::from_millis(10 * i)));
        }
        assert_eq!(pacer.errors(), 6);
        assert_eq!(pacer.pings(), 0);
    }
}
