//! Fuzz the CDR decoders of ROS 2 depth bags (`sensor_msgs/msg/Image`, `sensor_msgs/msg/CameraInfo`): any bytes
//! must decode or give a clear error, never a panic or an allocation sized by an unchecked length (image sides are
//! bounded before the pixel buffer grows).
#![no_main]

use libfuzzer_sys::fuzz_target;
use supine_drivers::ros_bag::{decode_camera_info, decode_depth_image};

fuzz_target!(|data: &[u8]| {
    let mut px = Vec::new();
    if let Ok(info) = decode_depth_image(data, &mut px) {
        assert_eq!(px.len(), info.width as usize * info.height as usize);
    }
    if let Ok(k) = decode_camera_info(data) {
        assert!(k.fx > 0.0 && k.fy > 0.0 && k.width > 0 && k.height > 0);
    }
});
