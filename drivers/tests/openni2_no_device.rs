//! libOpenNI2 on a machine without depth sensors (feature `openni2`; run by tests/run.sh with `--include-ignored`).
//! Its own test binary, so no .oni file opened by another test is in OpenNI2's device list.
#![cfg(feature = "openni2")]

use supine_drivers::openni2::{OpenNi2Source, list_devices};
use supine_drivers::source::SourceErrorKind;

#[test]
#[ignore = "needs libOpenNI2; run by tests/run.sh"]
fn enumeration_without_a_device_is_a_clear_no_device_error() {
    let devices = list_devices().unwrap();
    assert!(
        devices.is_empty(),
        "this test expects a machine without depth sensors: {devices:?}"
    );
    let e = OpenNi2Source::open(None).unwrap_err();
    assert_eq!(e.kind(), SourceErrorKind::NoDevice);
    assert!(e.to_string().contains("no OpenNI2 device found"), "{e}");
    let e = OpenNi2Source::open(Some("/nonexistent/supine.oni")).unwrap_err();
    assert_eq!(e.kind(), SourceErrorKind::NoDevice, "{e}");
}
