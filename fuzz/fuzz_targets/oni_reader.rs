//! Fuzz the pure-Rust .oni reader: any bytes must give frames or a clear error, never a panic, a hang or an
//! allocation driven by a length field (the reader sizes its buffers from the checked video mode only).
#![no_main]

use std::io::Cursor;

use libfuzzer_sys::fuzz_target;
use supine_drivers::oni::OniReader;

fuzz_target!(|data: &[u8]| {
    let Ok(mut reader) = OniReader::new(Cursor::new(data), "fuzz.oni") else {
        return;
    };
    // A file this small holds few frames; the cap only guards against a reader that would loop without progress.
    for _ in 0..256 {
        match reader.read_frame() {
            Ok(frame) => {
                let px = frame.depth_mm();
                assert_eq!(px.len(), frame.width() as usize * frame.height() as usize);
            }
            Err(_) => break,
        }
    }
});
