//! Hand-written FFI to libfreenect 0.5 (`/usr/include/libfreenect.h`, Debian `libfreenect-dev`) and the safe
//! event-thread/double-buffer machinery over it. All `unsafe` of the libfreenect backend lives here.
//!
//! Design: libfreenect delivers frames through a C callback that runs inside `freenect_process_events*` on whichever
//! thread pumps events. [`Kinect::open`] starts one event thread that pumps with a 100 ms timeout until told to stop.
//! The depth callback copies libfreenect's frame into the *back* buffer of a mutex-protected [`Shared`] slot and
//! signals a condvar; the consumer swaps back and front buffers (a pointer swap, no copy, no allocation) and lends
//! the front buffer. Drop stops the thread first, then stops depth, closes the device and shuts the context down, all
//! from the owning thread.

#![allow(unsafe_code)]

use std::ffi::{c_int, c_void};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// `FREENECT_DEVICE_CAMERA` (`freenect_device_flags`).
pub const DEVICE_CAMERA: c_int = 0x02;
/// `FREENECT_RESOLUTION_MEDIUM` (640x480).
pub const RESOLUTION_MEDIUM: c_int = 1;
/// `FREENECT_DEPTH_REGISTERED`: depth in mm aligned to the RGB image (`freenect_depth_format`).
pub const DEPTH_REGISTERED: c_int = 4;

/// `freenect_frame_mode` (libfreenect.h), 24 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct FrameMode {
    /// `uint32_t reserved`.
    pub reserved: u32,
    /// `freenect_resolution resolution`.
    pub resolution: c_int,
    /// `union { int32_t dummy; freenect_video_format video_format; freenect_depth_format depth_format; }`.
    pub format: i32,
    /// `int32_t bytes`.
    pub bytes: i32,
    /// `int16_t width`.
    pub width: i16,
    /// `int16_t height`.
    pub height: i16,
    /// `int8_t data_bits_per_pixel`.
    pub data_bits_per_pixel: i8,
    /// `int8_t padding_bits_per_pixel`.
    pub padding_bits_per_pixel: i8,
    /// `int8_t framerate`.
    pub framerate: i8,
    /// `int8_t is_valid`.
    pub is_valid: i8,
}

/// `struct _freenect_context` (opaque).
#[repr(C)]
pub struct FreenectContext {
    _private: [u8; 0],
}
/// `struct _freenect_device` (opaque).
#[repr(C)]
pub struct FreenectDevice {
    _private: [u8; 0],
}

/// `freenect_depth_cb`.
type DepthCb = extern "C" fn(dev: *mut FreenectDevice, depth: *mut c_void, timestamp: u32);

#[link(name = "freenect")]
unsafe extern "C" {
    fn freenect_init(ctx: *mut *mut FreenectContext, usb_ctx: *mut c_void) -> c_int;
    fn freenect_shutdown(ctx: *mut FreenectContext) -> c_int;
    fn freenect_process_events_timeout(ctx: *mut FreenectContext, timeout: *mut libc::timeval) -> c_int;
    fn freenect_num_devices(ctx: *mut FreenectContext) -> c_int;
    fn freenect_select_subdevices(ctx: *mut FreenectContext, subdevs: c_int);
    fn freenect_open_device(ctx: *mut FreenectContext, dev: *mut *mut FreenectDevice, index: c_int) -> c_int;
    fn freenect_close_device(dev: *mut FreenectDevice) -> c_int;
    fn freenect_set_user(dev: *mut FreenectDevice, user: *mut c_void);
    fn freenect_get_user(dev: *mut FreenectDevice) -> *mut c_void;
    fn freenect_set_depth_callback(dev: *mut FreenectDevice, cb: DepthCb);
    fn freenect_start_depth(dev: *mut FreenectDevice) -> c_int;
    fn freenect_stop_depth(dev: *mut FreenectDevice) -> c_int;
    fn freenect_find_depth_mode(res: c_int, fmt: c_int) -> FrameMode;
    fn freenect_set_depth_mode(dev: *mut FreenectDevice, mode: FrameMode) -> c_int;
}

/// Pixels of a 640x480 depth frame.
const PIXELS: usize = 640 * 480;

/// An initialised libfreenect context (camera subdevice only); shut down on drop.
struct Context(*mut FreenectContext);

// SAFETY: the context is used by the event thread (process_events) and the owner (open/close/start/stop), which
// libfreenect supports; it is shut down only after the event thread has been joined.
unsafe impl Send for Context {}
unsafe impl Sync for Context {}

impl Context {
    fn new() -> Result<Context, String> {
        let mut ctx = std::ptr::null_mut();
        // SAFETY: out-pointer; NULL usb context lets libfreenect create its own.
        let r = unsafe { freenect_init(&mut ctx, std::ptr::null_mut()) };
        if r < 0 || ctx.is_null() {
            return Err(format!("freenect_init failed ({r})"));
        }
        // SAFETY: `ctx` is a live context. Camera only: the motor and audio subdevices are not needed.
        unsafe { freenect_select_subdevices(ctx, DEVICE_CAMERA) };
        Ok(Context(ctx))
    }

    fn num_devices(&self) -> i32 {
        // SAFETY: live context.
        unsafe { freenect_num_devices(self.0) }
    }
}

impl Drop for Context {
    fn drop(&mut self) {
        // SAFETY: live context, shut down once; every device of it was closed before (field order in Kinect).
        unsafe {
            freenect_shutdown(self.0);
        }
    }
}

/// Count the Kinects libfreenect sees.
pub fn device_count() -> Result<usize, String> {
    let ctx = Context::new()?;
    let n = ctx.num_devices();
    if n < 0 {
        return Err(format!("freenect_num_devices failed ({n})"));
    }
    Ok(n as usize)
}

/// The slot the callback fills.
pub struct Slot {
    /// The back buffer (written by the callback).
    pub back: Vec<u16>,
    /// A frame is in `back` that the consumer has not taken.
    pub fresh: bool,
    /// Frames delivered by the callback so far.
    pub sequence: u32,
    /// When the latest frame arrived, µs since the device was opened.
    pub capture_us: u64,
    /// The event loop failed (device unplugged).
    pub failed: Option<String>,
}

/// State shared between the callback (event thread) and the consumer.
pub struct Shared {
    slot: Mutex<Slot>,
    ready: Condvar,
}

/// The outcome of [`Kinect::wait_frame`].
#[derive(Debug, PartialEq, Eq)]
pub enum Wait {
    /// A frame was swapped into the front buffer: (capture µs, sequence number).
    Frame(u64, u32),
    /// Nothing within the timeout.
    Timeout,
    /// The event loop failed.
    Failed(String),
}

extern "C" fn depth_callback(dev: *mut FreenectDevice, depth: *mut c_void, _timestamp: u32) {
    // SAFETY: the user pointer was set in `Kinect::open` to an `Arc<Shared>` that outlives the device (the Kinect
    // holds it and stops the event thread before dropping it); `depth` points at a 640x480 u16 frame owned by
    // libfreenect for the duration of this call (FREENECT_DEPTH_REGISTERED, checked at open).
    let (shared, src) = unsafe {
        let user = freenect_get_user(dev) as *const Shared;
        if user.is_null() || depth.is_null() {
            return;
        }
        (&*user, std::slice::from_raw_parts(depth as *const u16, PIXELS))
    };
    let now = crate::clock::MonotonicClock.now_us();
    let mut slot = shared.slot.lock().unwrap_or_else(|p| p.into_inner());
    if slot.back.len() == PIXELS {
        slot.back.copy_from_slice(src);
        slot.fresh = true;
        slot.sequence = slot.sequence.wrapping_add(1);
        slot.capture_us = now;
    }
    drop(slot);
    shared.ready.notify_one();
}

struct DevicePtr(*mut FreenectDevice);
// SAFETY: the device pointer is only used by the owning thread (start/stop/close); the event thread never touches it.
unsafe impl Send for DevicePtr {}

/// An open Kinect streaming registered depth; see the module docs for the threading design.
pub struct Kinect {
    thread: Option<JoinHandle<()>>,
    stop: Arc<AtomicBool>,
    shared: Arc<Shared>,
    dev: DevicePtr,
    ctx: Arc<Context>,
}

/// Why a Kinect could not be opened.
#[derive(Debug)]
pub enum OpenError {
    /// No device at that index (devices seen).
    NoDevice(usize),
    /// Anything else.
    Failed(String),
}

impl Kinect {
    /// Open Kinect `index` and start FREENECT_DEPTH_REGISTERED 640x480.
    pub fn open(index: u32) -> Result<Kinect, OpenError> {
        let ctx = Arc::new(Context::new().map_err(OpenError::Failed)?);
        let n = ctx.num_devices();
        if n < 0 {
            return Err(OpenError::Failed(format!("freenect_num_devices failed ({n})")));
        }
        if index as i64 >= n as i64 {
            return Err(OpenError::NoDevice(n as usize));
        }
        let mut dev = std::ptr::null_mut();
        // SAFETY: live context, out-pointer.
        let r = unsafe { freenect_open_device(ctx.0, &mut dev, index as c_int) };
        if r < 0 || dev.is_null() {
            return Err(OpenError::Failed(format!(
                "freenect_open_device({index}) failed ({r})"
            )));
        }
        let dev = DevicePtr(dev);
        let close = |dev: &DevicePtr| {
            // SAFETY: the device is open and closed once on this error path.
            unsafe { freenect_close_device(dev.0) };
        };
        // SAFETY: plain function returning a struct by value.
        let mode = unsafe { freenect_find_depth_mode(RESOLUTION_MEDIUM, DEPTH_REGISTERED) };
        if mode.is_valid == 0 || (mode.width, mode.height) != (640, 480) || mode.bytes != (PIXELS * 2) as i32
        {
            close(&dev);
            return Err(OpenError::Failed(
                "libfreenect has no 640x480 registered depth mode".into(),
            ));
        }
        // SAFETY: live device, valid mode from libfreenect.
        let r = unsafe { freenect_set_depth_mode(dev.0, mode) };
        if r < 0 {
            close(&dev);
            return Err(OpenError::Failed(format!("freenect_set_depth_mode failed ({r})")));
        }
        let shared = Arc::new(Shared {
            slot: Mutex::new(Slot {
                back: vec![0; PIXELS],
                fresh: false,
                sequence: 0,
                capture_us: 0,
                failed: None,
            }),
            ready: Condvar::new(),
        });
        // SAFETY: the user pointer stays valid while `shared` lives, which outlasts every callback (see Drop).
        unsafe {
            freenect_set_user(dev.0, Arc::as_ptr(&shared) as *mut c_void);
            freenect_set_depth_callback(dev.0, depth_callback);
        }
        // SAFETY: live device with mode and callback set.
        let r = unsafe { freenect_start_depth(dev.0) };
        if r < 0 {
            close(&dev);
            return Err(OpenError::Failed(format!("freenect_start_depth failed ({r})")));
        }
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (ctx, stop, shared) = (Arc::clone(&ctx), Arc::clone(&stop), Arc::clone(&shared));
            std::thread::Builder::new()
                .name("freenect-events".into())
                .spawn(move || event_loop(&ctx, &stop, &shared))
                .map_err(|e| OpenError::Failed(format!("spawning the freenect event thread: {e}")))?
        };
        Ok(Kinect {
            thread: Some(thread),
            stop,
            shared,
            dev,
            ctx,
        })
    }

    /// Wait up to `timeout` for a fresh frame and swap it into `front` (which must hold 640x480 pixels).
    pub fn wait_frame(&self, front: &mut Vec<u16>, timeout: Duration) -> Wait {
        let deadline = Instant::now() + timeout;
        let mut slot = self.shared.slot.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if let Some(e) = &slot.failed {
                return Wait::Failed(e.clone());
            }
            if slot.fresh {
                std::mem::swap(front, &mut slot.back);
                slot.fresh = false;
                return Wait::Frame(slot.capture_us, slot.sequence);
            }
            let now = Instant::now();
            if now >= deadline {
                return Wait::Timeout;
            }
            slot = self
                .shared
                .ready
                .wait_timeout(slot, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

fn event_loop(ctx: &Context, stop: &AtomicBool, shared: &Shared) {
    while !stop.load(Ordering::Acquire) {
        let mut tv = libc::timeval {
            tv_sec: 0,
            tv_usec: 100_000,
        };
        // SAFETY: live context (the Arc keeps it); `tv` is a valid timeval.
        let r = unsafe { freenect_process_events_timeout(ctx.0, &mut tv) };
        if r < 0 {
            let mut slot = shared.slot.lock().unwrap_or_else(|p| p.into_inner());
            slot.failed = Some(format!(
                "freenect_process_events failed ({r}): device disconnected?"
            ));
            drop(slot);
            shared.ready.notify_all();
            return;
        }
    }
}

impl Drop for Kinect {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        // SAFETY: the event thread is gone, so no callback runs any more; stop and close the device once. The
        // context is shut down when the last Arc (ours) drops right after.
        unsafe {
            freenect_stop_depth(self.dev.0);
            freenect_close_device(self.dev.0);
        }
        let _ = &self.ctx;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_mode_layout() {
        assert_eq!(size_of::<FrameMode>(), 24);
        assert_eq!(std::mem::offset_of!(FrameMode, width), 16);
        assert_eq!(std::mem::offset_of!(FrameMode, is_valid), 23);
    }

    #[test]
    fn the_library_knows_registered_vga_depth() {
        // Needs only libfreenect, no device.
        // SAFETY: plain function returning a struct by value.
        let mode = unsafe { freenect_find_depth_mode(RESOLUTION_MEDIUM, DEPTH_REGISTERED) };
        assert_eq!(
            (mode.is_valid, mode.width, mode.height, mode.bytes),
            (1, 640, 480, 614_400)
        );
        assert_eq!(mode.data_bits_per_pixel, 16);
    }
}
