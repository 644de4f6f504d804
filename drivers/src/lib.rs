//! supine-drivers: where supine meets hardware and files.
//!
//! Depth sources lend [`supine_core::depth::DepthFrame`]s; packet links carry `supine_core::wire` messages to and
//! from the arm controller. `unsafe` lives only in one `sys` module per FFI backend.

#[cfg(test)]
mod c_probe;
pub mod calib_host;
pub mod clock;
pub mod fault;
#[cfg(feature = "freenect")]
pub mod freenect;
pub mod kinect_raw;
pub mod link;
pub mod oni;
#[cfg(feature = "openni2")]
pub mod openni2;
pub mod recording;
pub mod ros_bag;
pub mod source;
pub mod tracker_host;
pub mod v4l2;

pub use source::{DepthSource, SourceError, SourceErrorKind, SourceSpec};
