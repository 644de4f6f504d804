//! Shared pieces of the link tools (`supine wire send`, `supine wire listen`, `supine info`): interrupt handling,
//! link counters and sequence accounting as JSON, and the links part of `supine info`.

use serde_json::{Map, Value, json};
use supine_drivers::link::{LinkCounters, SequenceAccounting};

pub use supine_drivers::link::signal::{catch_interrupts, interrupted};

/// Link counters as a JSON object (the keys scripts rely on: `sent`, `dropped`, `rx_messages`, `rx_errors`,
/// `reconnects`, ...).
pub fn counters_json(c: &LinkCounters) -> Value {
    let errors: Map<String, Value> = c
        .rx_errors
        .iter()
        .map(|(k, v)| (k.to_owned(), json!(v)))
        .collect();
    json!({
        "queued": c.queued,
        "sent": c.sent,
        "sent_bytes": c.sent_bytes,
        "dropped": c.dropped,
        "encode_errors": c.encode_errors,
        "rx_frames": c.rx_frames,
        "rx_messages": c.rx_messages,
        "rx_foreign": c.rx_foreign,
        "rx_errors_total": c.rx_errors.total(),
        "rx_errors": errors,
        "disconnects": c.disconnects,
        "reconnects": c.reconnects,
        "reconnect_failures": c.reconnect_failures,
        "io_errors": c.io_errors,
        "bus_off": c.bus_off,
    })
}

/// Sequence accounting as JSON: received, lost by gaps, out of order, per kind.
pub fn sequence_json(a: &SequenceAccounting) -> Value {
    let per_kind: Map<String, Value> = a
        .per_kind()
        .map(|(k, received, lost)| (k.name().to_owned(), json!({"received": received, "lost": lost})))
        .collect();
    json!({
        "received": a.received(),
        "lost": a.lost(),
        "out_of_order": a.out_of_order(),
        "restarts": a.restarts(),
        "per_kind": per_kind,
    })
}

/// The links part of `supine info`, as text: the link kinds this build speaks, whether the kernel has SocketCAN,
/// the serial ports (USB adapters, SLCAN dongles, on-board UARTs with a driver behind them) and CAN interfaces
/// visible now. Nothing is opened.
pub fn info_text() -> String {
    let mut s = String::from("links:\n");
    s.push_str("  kinds: stdout, serial:PATH[@BAUD], slcan:PATH[@BAUD], can:IFACE, file:PATH\n");
    s.push_str(&format!("  socketcan: {}\n", socketcan_support()));
    let ports = serial_ports();
    if ports.is_empty() {
        s.push_str("  serial: no USB or ACM serial ports (/dev/ttyUSB*, /dev/ttyACM*)\n");
    }
    for p in ports {
        s.push_str(&format!("  serial: {p}\n"));
    }
    let ifaces = can_interfaces();
    if ifaces.is_empty() {
        s.push_str("  can: no CAN network interfaces\n");
    }
    for i in ifaces {
        s.push_str(&format!("  can: {i}  (use can:{i})\n"));
    }
    s
}

/// USB serial adapters and CDC-ACM devices (where SLCAN dongles and arm-controller UARTs appear), with their
/// stable `/dev/serial/by-id` names when udev made them.
fn serial_ports() -> Vec<String> {
    let mut ports: Vec<String> = std::fs::read_dir("/dev")
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with("ttyUSB") || n.starts_with("ttyACM"))
                .map(|n| format!("/dev/{n}"))
                .collect()
        })
        .unwrap_or_default();
    if let Ok(entries) = std::fs::read_dir("/dev/serial/by-id") {
        for e in entries.filter_map(|e| e.ok()) {
            let link = e.path();
            let target = std::fs::canonicalize(&link)
                .map(|t| t.display().to_string())
                .unwrap_or_default();
            ports.push(format!("{} -> {target}", link.display()));
        }
    }
    ports.sort();
    ports
}

/// Network interfaces of type `ARPHRD_CAN` (280, `linux/if_arp.h`), read from sysfs.
fn can_interfaces() -> Vec<String> {
    let mut out: Vec<String> = std::fs::read_dir("/sys/class/net")
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter(|e| std::fs::read_to_string(e.path().join("type")).is_ok_and(|t| t.trim() == "280"))
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    out
}

/// Whether this kernel offers SocketCAN: `/proc/net/can` exists once the CAN core is loaded; a kernel built
/// without `CONFIG_CAN` has none.
pub fn socketcan_support() -> &'static str {
    if std::path::Path::new("/proc/net/can").exists() {
        "available"
    } else {
        "not available in this kernel (use slcan:PATH with a serial SLCAN adapter)"
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use supine_drivers::link::RxError;

    #[test]
    fn info_text_names_kinds_and_socketcan() {
        let s = info_text();
        assert!(s.starts_with("links:\n"), "{s}");
        assert!(
            s.contains("slcan:PATH[@BAUD]") && s.contains("socketcan: "),
            "{s}"
        );
        assert!(s.contains("serial: ") && s.contains("can: "), "{s}");
    }

    #[test]
    fn counters_json_has_every_error_class() {
        let mut c = LinkCounters::default();
        c.rx_errors.add(RxError::Crc);
        c.sent = 3;
        let v = counters_json(&c);
        assert_eq!(v["sent"], 3);
        assert_eq!(v["rx_errors"]["crc"], 1);
        assert_eq!(v["rx_errors_total"], 1);
        assert_eq!(v["rx_errors"].as_object().unwrap().len(), RxError::ALL.len());
    }
}
