//! Hand-written FFI to libOpenNI2 (Debian `libopenni2-dev`, 2.2.0.33) and the RAII wrappers over it. All `unsafe` of
//! the OpenNI2 backend lives here.
//!
//! The headers (`/usr/include/openni2/OniCAPI.h` etc.) are C++-only (`typedef _OniDevice*` needs C++), but the
//! symbols are plain `extern "C"`, so they are declared here by hand; every item names its header. The test
//! `layouts_match_the_openni2_headers` compiles a C++ probe with g++ against the installed headers and compares sizes,
//! offsets and constants.
//!
//! Lifetimes: [`Context`] proves the one process-wide `oniInitialize` happened (see its docs for why there is no
//! `oniShutdown`); every [`Frame`] borrows its stream, and the owner drops recorder → stream (stop, destroy) →
//! device (close), in that order; a playback device's streams are destroyed only after the device closes
//! ([`Device::is_playback`]).
#![allow(unsafe_code)]

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::marker::PhantomData;
use std::sync::{Arc, Mutex, OnceLock};

// ---- OniCEnums.h ----
/// `OniStatus` (OniCEnums.h).
pub type OniStatus = c_int;
/// `ONI_STATUS_OK`.
pub const STATUS_OK: OniStatus = 0;
/// `ONI_STATUS_ERROR`.
pub const STATUS_ERROR: OniStatus = 1;
/// `ONI_STATUS_NOT_SUPPORTED`.
pub const STATUS_NOT_SUPPORTED: OniStatus = 3;
/// `ONI_STATUS_NO_DEVICE`.
pub const STATUS_NO_DEVICE: OniStatus = 6;
/// `ONI_STATUS_TIME_OUT`.
pub const STATUS_TIME_OUT: OniStatus = 102;
/// `OniSensorType ONI_SENSOR_DEPTH`.
pub const SENSOR_DEPTH: c_int = 3;
/// `OniPixelFormat ONI_PIXEL_FORMAT_DEPTH_1_MM`.
pub const PIXEL_FORMAT_DEPTH_1_MM: c_int = 100;
/// `OniPixelFormat ONI_PIXEL_FORMAT_DEPTH_100_UM`.
pub const PIXEL_FORMAT_DEPTH_100_UM: c_int = 101;
/// `ONI_TIMEOUT_FOREVER` (OniCEnums.h `_OniTimeoutConstants`).
#[allow(dead_code)] // checked by the layout test; the source always passes a finite timeout
pub const TIMEOUT_FOREVER: c_int = -1;

// ---- OniCProperties.h ----
/// `ONI_STREAM_PROPERTY_HORIZONTAL_FOV` (float, radians).
pub const STREAM_PROPERTY_HORIZONTAL_FOV: c_int = 1;
/// `ONI_STREAM_PROPERTY_VERTICAL_FOV` (float, radians).
pub const STREAM_PROPERTY_VERTICAL_FOV: c_int = 2;
/// `ONI_STREAM_PROPERTY_VIDEO_MODE` (OniVideoMode).
pub const STREAM_PROPERTY_VIDEO_MODE: c_int = 3;
/// `ONI_STREAM_PROPERTY_MAX_VALUE` (int).
#[allow(dead_code)] // checked by the layout test; depth in mm needs no maximum
pub const STREAM_PROPERTY_MAX_VALUE: c_int = 4;
/// `ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES` (int).
pub const STREAM_PROPERTY_NUMBER_OF_FRAMES: c_int = 8;
/// `ONI_DEVICE_PROPERTY_PLAYBACK_SPEED` (float; -1.0 = manual, one frame per read).
pub const DEVICE_PROPERTY_PLAYBACK_SPEED: c_int = 100;
/// `ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED` (OniBool).
pub const DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED: c_int = 101;

// ---- OniVersion.h ----
/// `ONI_API_VERSION` = `ONI_CREATE_API_VERSION(2, 2)` = 2·1000 + 2.
pub const API_VERSION: c_int = 2002;

// ---- OniCTypes.h ----
/// `ONI_MAX_STR`.
pub const MAX_STR: usize = 256;

/// `OniVideoMode` (OniCTypes.h), 16 bytes.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OniVideoMode {
    /// `OniPixelFormat pixelFormat`.
    pub pixel_format: c_int,
    /// `int resolutionX`.
    pub resolution_x: c_int,
    /// `int resolutionY`.
    pub resolution_y: c_int,
    /// `int fps`.
    pub fps: c_int,
}

/// `OniSensorInfo` (OniCTypes.h), 16 bytes.
#[repr(C)]
#[derive(Debug)]
pub struct OniSensorInfo {
    /// `OniSensorType sensorType`.
    pub sensor_type: c_int,
    /// `int numSupportedVideoModes`.
    pub num_supported_video_modes: c_int,
    /// `OniVideoMode *pSupportedVideoModes`.
    pub supported_video_modes: *const OniVideoMode,
}

/// `OniDeviceInfo` (OniCTypes.h), 772 bytes.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct OniDeviceInfo {
    /// `char uri[ONI_MAX_STR]`.
    pub uri: [c_char; MAX_STR],
    /// `char vendor[ONI_MAX_STR]`.
    pub vendor: [c_char; MAX_STR],
    /// `char name[ONI_MAX_STR]`.
    pub name: [c_char; MAX_STR],
    /// `uint16_t usbVendorId`.
    pub usb_vendor_id: u16,
    /// `uint16_t usbProductId`.
    pub usb_product_id: u16,
}

/// `OniFrame` (OniCTypes.h), 80 bytes.
#[repr(C)]
#[derive(Debug)]
pub struct OniFrame {
    /// `int dataSize`.
    pub data_size: c_int,
    /// `void* data`.
    pub data: *mut c_void,
    /// `OniSensorType sensorType`.
    pub sensor_type: c_int,
    /// `uint64_t timestamp` (µs).
    pub timestamp: u64,
    /// `int frameIndex`.
    pub frame_index: c_int,
    /// `int width`.
    pub width: c_int,
    /// `int height`.
    pub height: c_int,
    /// `OniVideoMode videoMode`.
    pub video_mode: OniVideoMode,
    /// `OniBool croppingEnabled`.
    pub cropping_enabled: c_int,
    /// `int cropOriginX`.
    pub crop_origin_x: c_int,
    /// `int cropOriginY`.
    pub crop_origin_y: c_int,
    /// `int stride` (bytes per row).
    pub stride: c_int,
}

/// `OniCropping` (OniCTypes.h), 20 bytes.
#[allow(dead_code)] // layout checked by the tests; cropping is never enabled
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct OniCropping {
    /// `int enabled`.
    pub enabled: c_int,
    /// `int originX`.
    pub origin_x: c_int,
    /// `int originY`.
    pub origin_y: c_int,
    /// `int width`.
    pub width: c_int,
    /// `int height`.
    pub height: c_int,
}

/// `OniSeek` (OniCTypes.h), 16 bytes. Declared for the layout test only: seeking crashes the Debian player.
#[allow(dead_code)]
#[repr(C)]
#[derive(Debug)]
pub struct OniSeek {
    /// `int frameIndex`.
    pub frame_index: c_int,
    /// `OniStreamHandle stream`.
    pub stream: *mut OniStreamOpaque,
}

/// `struct _OniDevice` (opaque).
#[repr(C)]
pub struct OniDeviceOpaque {
    _private: [u8; 0],
}
/// `struct _OniStream` (opaque).
#[repr(C)]
pub struct OniStreamOpaque {
    _private: [u8; 0],
}
/// `struct _OniRecorder` (opaque).
#[repr(C)]
pub struct OniRecorderOpaque {
    _private: [u8; 0],
}

// ---- OniCAPI.h ----
#[link(name = "OpenNI2")]
unsafe extern "C" {
    fn oniInitialize(api_version: c_int) -> OniStatus;
    fn oniGetDeviceList(devices: *mut *mut OniDeviceInfo, num_devices: *mut c_int) -> OniStatus;
    fn oniReleaseDeviceList(devices: *mut OniDeviceInfo) -> OniStatus;
    fn oniWaitForAnyStream(
        streams: *mut *mut OniStreamOpaque,
        num_streams: c_int,
        stream_index: *mut c_int,
        timeout: c_int,
    ) -> OniStatus;
    fn oniGetExtendedError() -> *const c_char;
    fn oniDeviceOpen(uri: *const c_char, device: *mut *mut OniDeviceOpaque) -> OniStatus;
    fn oniDeviceClose(device: *mut OniDeviceOpaque) -> OniStatus;
    fn oniDeviceGetInfo(device: *mut OniDeviceOpaque, info: *mut OniDeviceInfo) -> OniStatus;
    fn oniDeviceGetSensorInfo(device: *mut OniDeviceOpaque, sensor_type: c_int) -> *const OniSensorInfo;
    fn oniDeviceCreateStream(
        device: *mut OniDeviceOpaque,
        sensor_type: c_int,
        stream: *mut *mut OniStreamOpaque,
    ) -> OniStatus;
    fn oniDeviceSetProperty(
        device: *mut OniDeviceOpaque,
        property_id: c_int,
        data: *const c_void,
        data_size: c_int,
    ) -> OniStatus;
    fn oniDeviceIsPropertySupported(device: *mut OniDeviceOpaque, property_id: c_int) -> c_int;
    fn oniStreamDestroy(stream: *mut OniStreamOpaque);
    fn oniStreamStart(stream: *mut OniStreamOpaque) -> OniStatus;
    fn oniStreamStop(stream: *mut OniStreamOpaque);
    fn oniStreamReadFrame(stream: *mut OniStreamOpaque, frame: *mut *mut OniFrame) -> OniStatus;
    fn oniStreamSetProperty(
        stream: *mut OniStreamOpaque,
        property_id: c_int,
        data: *const c_void,
        data_size: c_int,
    ) -> OniStatus;
    fn oniStreamGetProperty(
        stream: *mut OniStreamOpaque,
        property_id: c_int,
        data: *mut c_void,
        data_size: *mut c_int,
    ) -> OniStatus;
    fn oniFrameRelease(frame: *mut OniFrame);
    fn oniCreateRecorder(file_name: *const c_char, recorder: *mut *mut OniRecorderOpaque) -> OniStatus;
    fn oniRecorderAttachStream(
        recorder: *mut OniRecorderOpaque,
        stream: *mut OniStreamOpaque,
        allow_lossy_compression: c_int,
    ) -> OniStatus;
    fn oniRecorderStart(recorder: *mut OniRecorderOpaque) -> OniStatus;
    fn oniRecorderStop(recorder: *mut OniRecorderOpaque);
    fn oniRecorderDestroy(recorder: *mut *mut OniRecorderOpaque) -> OniStatus;
}

/// A failed OpenNI2 call: the status and `oniGetExtendedError()`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OniError {
    /// The `OniStatus`.
    pub status: OniStatus,
    /// The call that failed.
    pub call: &'static str,
    /// OpenNI's extended error text.
    pub detail: String,
}

impl std::fmt::Display for OniError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} failed with status {}", self.call, self.status)?;
        if !self.detail.is_empty() {
            write!(f, ": {}", self.detail.trim())?;
        }
        Ok(())
    }
}

fn check(status: OniStatus, call: &'static str) -> Result<(), OniError> {
    if status == STATUS_OK {
        return Ok(());
    }
    // SAFETY: oniGetExtendedError returns NULL or a NUL-terminated string owned by the library, valid until the
    // next OpenNI call on this thread; we copy it at once.
    let detail = unsafe {
        let p = oniGetExtendedError();
        if p.is_null() {
            String::new()
        } else {
            CStr::from_ptr(p).to_string_lossy().into_owned()
        }
    };
    Err(OniError { status, call, detail })
}

/// The one `oniInitialize` of this process (its status, kept for every later caller).
static INIT: OnceLock<Result<(), OniError>> = OnceLock::new();

/// Proof that libOpenNI2 is initialised.
///
/// OpenNI2 is initialised once per process and never shut down: calling `oniInitialize` again after `oniShutdown`
/// crashes the Debian 2.2.0.33 build (SIGSEGV, seen when a second test opened a file after the first had shut the
/// library down), and the OS reclaims everything at exit. Devices, streams and frames are still closed by RAII.
#[derive(Debug, Clone)]
pub struct Context(());

impl Context {
    /// Initialise OpenNI2 on first use.
    pub fn acquire() -> Result<Context, OniError> {
        // SAFETY: OnceLock runs this exactly once, so oniInitialize is never called concurrently or twice.
        let init = INIT.get_or_init(|| check(unsafe { oniInitialize(API_VERSION) }, "oniInitialize"));
        init.clone().map(|()| Context(()))
    }

    /// The devices OpenNI2's drivers enumerate.
    pub fn devices(&self) -> Result<Vec<DeviceInfo>, OniError> {
        let mut list: *mut OniDeviceInfo = std::ptr::null_mut();
        let mut n: c_int = 0;
        // SAFETY: valid out-pointers; the library is initialised (we hold a Context).
        check(unsafe { oniGetDeviceList(&mut list, &mut n) }, "oniGetDeviceList")?;
        let mut out = Vec::new();
        if !list.is_null() {
            for i in 0..n.max(0) as usize {
                // SAFETY: the library returned `n` contiguous OniDeviceInfo at `list`, valid until released below.
                let info = unsafe { &*list.add(i) };
                out.push(DeviceInfo::from_raw(info));
            }
            // SAFETY: `list` came from oniGetDeviceList and is released exactly once.
            unsafe {
                oniReleaseDeviceList(list);
            }
        }
        Ok(out)
    }
}

/// A device as OpenNI2 describes it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceInfo {
    /// URI to open it with.
    pub uri: String,
    /// Vendor.
    pub vendor: String,
    /// Name.
    pub name: String,
    /// USB vendor id.
    pub usb_vendor_id: u16,
    /// USB product id.
    pub usb_product_id: u16,
}

fn c_chars(chars: &[c_char]) -> String {
    let bytes: Vec<u8> = chars.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

impl DeviceInfo {
    fn from_raw(info: &OniDeviceInfo) -> Self {
        DeviceInfo {
            uri: c_chars(&info.uri),
            vendor: c_chars(&info.vendor),
            name: c_chars(&info.name),
            usb_vendor_id: info.usb_vendor_id,
            usb_product_id: info.usb_product_id,
        }
    }
}

/// An open OpenNI2 device (a sensor or an .oni file); closed on drop.
#[derive(Debug)]
pub struct Device {
    handle: *mut OniDeviceOpaque,
    ctx: Context,
    /// For a playback device, the streams whose destruction waits for the device's close.
    deferred: Option<Arc<Mutex<Deferred>>>,
}

/// The streams of a playback device that were dropped before it, and whether it is closed.
///
/// Why: the file driver's player thread walks the device's stream list without its lock (OpenNI2
/// `Source/Drivers/OniFile/PlayerDevice.cpp`, `MainLoop`), so a stream destroyed while that thread runs can be freed
/// under it: SIGSEGV in libOniFile.so, in 6 of 20 runs of `openni2_interop` beside other work on the 2-core host and
/// in 40 of 40 beside two busy loops (0 of 40 with the order below). Closing
/// the device first joins the player thread (`PlayerDevice::close`), and after the close OpenNI's core no longer
/// calls into the driver when a stream is destroyed (`Source/Core/OniStream.cpp`, `~VideoStream`: no
/// `deviceDestroyStream` once the device's handle is NULL), so a playback stream is stopped on drop (the driver
/// then ignores the player's frames: `PlayerStream::OnNewDataCallback`) and destroyed after the device closes.
#[derive(Debug, Default)]
struct Deferred {
    closed: bool,
    streams: Vec<StreamPtr>,
}

/// A stream handle waiting in [`Deferred`].
#[derive(Debug)]
struct StreamPtr(*mut OniStreamOpaque);

// SAFETY: see `Device`: the handle is only destroyed, once, by whichever owner drops last.
unsafe impl Send for StreamPtr {}

fn lock(d: &Mutex<Deferred>) -> std::sync::MutexGuard<'_, Deferred> {
    // A panic while holding this lock leaves a consistent list (pushes and a flag); keep closing.
    d.lock().unwrap_or_else(|e| e.into_inner())
}

impl Device {
    /// Open `uri` (`None` = any device).
    pub fn open(ctx: &Context, uri: Option<&str>) -> Result<Device, OniError> {
        let c = match uri {
            Some(u) => Some(CString::new(u).map_err(|_| OniError {
                status: STATUS_ERROR,
                call: "oniDeviceOpen",
                detail: "URI contains a NUL byte".into(),
            })?),
            None => None,
        };
        let mut handle = std::ptr::null_mut();
        let ptr = c.as_ref().map_or(std::ptr::null(), |c| c.as_ptr());
        // SAFETY: `ptr` is NULL (any device) or a NUL-terminated string alive for the call; `handle` is an out-param.
        check(unsafe { oniDeviceOpen(ptr, &mut handle) }, "oniDeviceOpen")?;
        let mut device = Device {
            handle,
            ctx: ctx.clone(),
            deferred: None,
        };
        if device.supports(DEVICE_PROPERTY_PLAYBACK_SPEED)
            && device.supports(DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED)
        {
            device.deferred = Some(Arc::default());
        }
        Ok(device)
    }

    /// Whether this is a playback device (an .oni file: it has the playback speed and repeat properties).
    pub fn is_playback(&self) -> bool {
        self.deferred.is_some()
    }

    /// The device's description.
    pub fn info(&self) -> Result<DeviceInfo, OniError> {
        // SAFETY: OniDeviceInfo is plain data; zero is valid. `self.handle` is open.
        let mut raw: OniDeviceInfo = unsafe { std::mem::zeroed() };
        check(
            unsafe { oniDeviceGetInfo(self.handle, &mut raw) },
            "oniDeviceGetInfo",
        )?;
        Ok(DeviceInfo::from_raw(&raw))
    }

    /// Whether the device supports a property (an .oni file supports the playback properties 100, 101).
    pub fn supports(&self, property: c_int) -> bool {
        // SAFETY: `self.handle` is open.
        unsafe { oniDeviceIsPropertySupported(self.handle, property) != 0 }
    }

    /// Set a float device property (e.g. PLAYBACK_SPEED; the data size must be exactly 4).
    pub fn set_f32(&self, property: c_int, value: f32) -> Result<(), OniError> {
        // SAFETY: `value` is a live f32 and we pass its exact size.
        check(
            unsafe { oniDeviceSetProperty(self.handle, property, (&value as *const f32).cast(), 4) },
            "oniDeviceSetProperty",
        )
    }

    /// Set an int/OniBool device property.
    pub fn set_i32(&self, property: c_int, value: c_int) -> Result<(), OniError> {
        // SAFETY: `value` is a live c_int and we pass its exact size.
        check(
            unsafe { oniDeviceSetProperty(self.handle, property, (&value as *const c_int).cast(), 4) },
            "oniDeviceSetProperty",
        )
    }

    /// The video modes of the depth sensor, if it has one.
    pub fn depth_modes(&self) -> Vec<OniVideoMode> {
        // SAFETY: `self.handle` is open; the returned pointer is NULL or owned by the device and valid while it is
        // open; we copy the modes out at once.
        unsafe {
            let info = oniDeviceGetSensorInfo(self.handle, SENSOR_DEPTH);
            if info.is_null() || (*info).supported_video_modes.is_null() {
                return Vec::new();
            }
            let n = (*info).num_supported_video_modes.max(0) as usize;
            std::slice::from_raw_parts((*info).supported_video_modes, n).to_vec()
        }
    }

    /// Create the depth stream (not started).
    pub fn create_depth_stream(&self) -> Result<Stream, OniError> {
        let mut handle = std::ptr::null_mut();
        // SAFETY: `self.handle` is open; `handle` is an out-param.
        check(
            unsafe { oniDeviceCreateStream(self.handle, SENSOR_DEPTH, &mut handle) },
            "oniDeviceCreateStream",
        )?;
        Ok(Stream {
            handle,
            started: false,
            deferred: self.deferred.clone(),
            _ctx: self.ctx.clone(),
        })
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the handle is open and closed exactly once. A live device's streams were destroyed before (field
        // order in OpenNi2Source); a playback device's dropped streams wait in `deferred` and are destroyed exactly
        // once here, after the close (see `Deferred`).
        unsafe {
            oniDeviceClose(self.handle);
        }
        if let Some(d) = &self.deferred {
            let mut d = lock(d);
            d.closed = true;
            for s in d.streams.drain(..) {
                // SAFETY: a stream handle of this device, stopped and not destroyed yet (its owner is gone).
                unsafe {
                    oniStreamDestroy(s.0);
                }
            }
        }
    }
}

// SAFETY: OpenNI2 handles may be used from any thread (the library locks internally); we never use one handle from
// two threads at once because the owners need `&mut` for frame reads.
unsafe impl Send for Device {}

/// A depth stream; stopped and destroyed on drop (a playback device's: destroyed once the device is closed).
#[derive(Debug)]
pub struct Stream {
    handle: *mut OniStreamOpaque,
    started: bool,
    /// The playback device's deferral ([`Deferred`]); `None` for a live device.
    deferred: Option<Arc<Mutex<Deferred>>>,
    _ctx: Context,
}

// SAFETY: see `Device`.
unsafe impl Send for Stream {}

impl Stream {
    /// Set the video mode (live devices only; files refuse).
    pub fn set_video_mode(&self, mode: OniVideoMode) -> Result<(), OniError> {
        // SAFETY: `mode` is a live OniVideoMode of exactly 16 bytes.
        check(
            unsafe {
                oniStreamSetProperty(
                    self.handle,
                    STREAM_PROPERTY_VIDEO_MODE,
                    (&mode as *const OniVideoMode).cast(),
                    size_of::<OniVideoMode>() as c_int,
                )
            },
            "oniStreamSetProperty(VIDEO_MODE)",
        )
    }

    /// The current video mode.
    pub fn video_mode(&self) -> Result<OniVideoMode, OniError> {
        let mut mode = OniVideoMode::default();
        let mut size = size_of::<OniVideoMode>() as c_int;
        // SAFETY: `mode` is a writable 16-byte buffer and `size` says so.
        check(
            unsafe {
                oniStreamGetProperty(
                    self.handle,
                    STREAM_PROPERTY_VIDEO_MODE,
                    (&mut mode as *mut OniVideoMode).cast(),
                    &mut size,
                )
            },
            "oniStreamGetProperty(VIDEO_MODE)",
        )?;
        Ok(mode)
    }

    /// A float stream property (FOVs).
    pub fn get_f32(&self, property: c_int) -> Result<f32, OniError> {
        let mut v: f32 = 0.0;
        let mut size: c_int = 4;
        // SAFETY: `v` is a writable 4-byte buffer and `size` says so.
        check(
            unsafe { oniStreamGetProperty(self.handle, property, (&mut v as *mut f32).cast(), &mut size) },
            "oniStreamGetProperty",
        )?;
        Ok(v)
    }

    /// An int stream property (MAX_VALUE, NUMBER_OF_FRAMES).
    pub fn get_i32(&self, property: c_int) -> Result<c_int, OniError> {
        let mut v: c_int = 0;
        let mut size: c_int = 4;
        // SAFETY: `v` is a writable 4-byte buffer and `size` says so.
        check(
            unsafe { oniStreamGetProperty(self.handle, property, (&mut v as *mut c_int).cast(), &mut size) },
            "oniStreamGetProperty",
        )?;
        Ok(v)
    }

    /// Start streaming.
    pub fn start(&mut self) -> Result<(), OniError> {
        // SAFETY: the handle is a live stream.
        check(unsafe { oniStreamStart(self.handle) }, "oniStreamStart")?;
        self.started = true;
        Ok(())
    }

    /// Wait up to `timeout_ms` (-1 = forever) for a frame; `Ok(false)` on timeout.
    pub fn wait(&mut self, timeout_ms: c_int) -> Result<bool, OniError> {
        let mut streams = [self.handle];
        let mut index: c_int = -1;
        // SAFETY: one valid stream handle in a live array; `index` is an out-param.
        let status = unsafe { oniWaitForAnyStream(streams.as_mut_ptr(), 1, &mut index, timeout_ms) };
        if status == STATUS_TIME_OUT {
            return Ok(false);
        }
        check(status, "oniWaitForAnyStream").map(|()| true)
    }

    /// Read the next frame (blocks until one exists: call [`Stream::wait`] first).
    pub fn read_frame(&mut self) -> Result<Frame<'_>, OniError> {
        let mut frame = std::ptr::null_mut();
        // SAFETY: the stream is live; `frame` is an out-param.
        check(
            unsafe { oniStreamReadFrame(self.handle, &mut frame) },
            "oniStreamReadFrame",
        )?;
        if frame.is_null() {
            return Err(OniError {
                status: STATUS_ERROR,
                call: "oniStreamReadFrame",
                detail: "NULL frame".into(),
            });
        }
        Ok(Frame {
            ptr: frame,
            _stream: PhantomData,
        })
    }
}

impl Drop for Stream {
    fn drop(&mut self) {
        if self.started {
            // SAFETY: the handle is live; no Frame borrows it (they borrow `&mut self`).
            unsafe {
                oniStreamStop(self.handle);
            }
        }
        if let Some(d) = &self.deferred {
            let mut d = lock(d);
            if !d.closed {
                // The device destroys it after its close (see `Deferred`).
                d.streams.push(StreamPtr(self.handle));
                return;
            }
        }
        // SAFETY: the handle is destroyed exactly once: here, or by the device if it was deferred above.
        unsafe {
            oniStreamDestroy(self.handle);
        }
    }
}

/// A frame read from a stream; released on drop.
#[derive(Debug)]
pub struct Frame<'s> {
    ptr: *mut OniFrame,
    _stream: PhantomData<&'s mut Stream>,
}

impl Frame<'_> {
    fn raw(&self) -> &OniFrame {
        // SAFETY: `ptr` is a frame the library gave us and that we have not released yet.
        unsafe { &*self.ptr }
    }

    /// (width, height, stride in bytes, timestamp µs, frame index, pixel format).
    pub fn meta(&self) -> (i32, i32, i32, u64, i32, i32) {
        let f = self.raw();
        (
            f.width,
            f.height,
            f.stride,
            f.timestamp,
            f.frame_index,
            f.video_mode.pixel_format,
        )
    }

    /// The frame's data as bytes.
    pub fn data(&self) -> &[u8] {
        let f = self.raw();
        if f.data.is_null() || f.data_size <= 0 {
            return &[];
        }
        // SAFETY: the library guarantees `data` points at `dataSize` readable bytes while the frame is held.
        unsafe { std::slice::from_raw_parts(f.data as *const u8, f.data_size as usize) }
    }
}

impl Drop for Frame<'_> {
    fn drop(&mut self) {
        // SAFETY: released exactly once.
        unsafe { oniFrameRelease(self.ptr) };
    }
}

/// OpenNI2's own recorder attached to a stream (used to produce reference files); destroyed (file finished) on drop.
#[derive(Debug)]
pub struct Recorder {
    handle: *mut OniRecorderOpaque,
    _ctx: Context,
}

// SAFETY: see `Device`.
unsafe impl Send for Recorder {}

impl Recorder {
    /// Create a recorder writing `path`, attach `stream` (lossless) and start it.
    pub fn start(ctx: &Context, path: &str, stream: &Stream) -> Result<Recorder, OniError> {
        let c = CString::new(path).map_err(|_| OniError {
            status: STATUS_ERROR,
            call: "oniCreateRecorder",
            detail: "path contains a NUL byte".into(),
        })?;
        let mut handle = std::ptr::null_mut();
        // SAFETY: `c` is a NUL-terminated path alive for the call; `handle` is an out-param.
        check(
            unsafe { oniCreateRecorder(c.as_ptr(), &mut handle) },
            "oniCreateRecorder",
        )?;
        let rec = Recorder {
            handle,
            _ctx: ctx.clone(),
        };
        // SAFETY: both handles are live.
        check(
            unsafe { oniRecorderAttachStream(rec.handle, stream.handle, 0) },
            "oniRecorderAttachStream",
        )?;
        // SAFETY: the recorder is live with one stream attached.
        check(unsafe { oniRecorderStart(rec.handle) }, "oniRecorderStart")?;
        Ok(rec)
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // SAFETY: the handle is live; destroy detaches streams, writes END and invalidates it, exactly once.
        unsafe {
            oniRecorderStop(self.handle);
            oniRecorderDestroy(&mut self.handle);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::offset_of;

    #[test]
    fn sizes_match_the_reference_measurements() {
        assert_eq!(size_of::<OniFrame>(), 80);
        assert_eq!(offset_of!(OniFrame, data), 8);
        assert_eq!(offset_of!(OniFrame, timestamp), 24);
        assert_eq!(offset_of!(OniFrame, video_mode), 44);
        assert_eq!(offset_of!(OniFrame, stride), 72);
        assert_eq!(size_of::<OniVideoMode>(), 16);
        assert_eq!(size_of::<OniDeviceInfo>(), 772);
        assert_eq!(offset_of!(OniDeviceInfo, usb_product_id), 770);
        assert_eq!(size_of::<OniSensorInfo>(), 16);
        assert_eq!(size_of::<OniCropping>(), 20);
        assert_eq!(size_of::<OniSeek>(), 16);
    }

    /// Compiles a C++ probe with g++ against /usr/include/openni2 and compares sizes, offsets and constants.
    #[test]
    fn layouts_match_the_openni2_headers() {
        let c = crate::c_probe::run(
            &crate::c_probe::Compiler {
                env_var: "CXX",
                default: "g++",
            },
            &["-I/usr/include/openni2"],
            "probe.cpp",
            r#"#include <cstdio>
#include <cstddef>
#include <OniCAPI.h>
#include <OniVersion.h>
#define P(name, v) std::printf("%s %ld\n", name, (long)(v))
int main() {
  P("frame", sizeof(OniFrame)); P("frame.data", offsetof(OniFrame, data));
  P("frame.timestamp", offsetof(OniFrame, timestamp)); P("frame.frameIndex", offsetof(OniFrame, frameIndex));
  P("frame.videoMode", offsetof(OniFrame, videoMode)); P("frame.stride", offsetof(OniFrame, stride));
  P("videomode", sizeof(OniVideoMode)); P("deviceinfo", sizeof(OniDeviceInfo));
  P("deviceinfo.usbVendorId", offsetof(OniDeviceInfo, usbVendorId)); P("sensorinfo", sizeof(OniSensorInfo));
  P("sensorinfo.modes", offsetof(OniSensorInfo, pSupportedVideoModes));
  P("cropping", sizeof(OniCropping)); P("seek", sizeof(OniSeek));
  P("STATUS_NO_DEVICE", ONI_STATUS_NO_DEVICE); P("STATUS_TIME_OUT", ONI_STATUS_TIME_OUT);
  P("SENSOR_DEPTH", ONI_SENSOR_DEPTH); P("DEPTH_1_MM", ONI_PIXEL_FORMAT_DEPTH_1_MM);
  P("DEPTH_100_UM", ONI_PIXEL_FORMAT_DEPTH_100_UM); P("HFOV", ONI_STREAM_PROPERTY_HORIZONTAL_FOV);
  P("VFOV", ONI_STREAM_PROPERTY_VERTICAL_FOV); P("VIDEO_MODE", ONI_STREAM_PROPERTY_VIDEO_MODE);
  P("MAX_VALUE", ONI_STREAM_PROPERTY_MAX_VALUE); P("NUMBER_OF_FRAMES", ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES);
  P("PLAYBACK_SPEED", ONI_DEVICE_PROPERTY_PLAYBACK_SPEED);
  P("PLAYBACK_REPEAT", ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED);
  P("API_VERSION", ONI_API_VERSION); P("TIMEOUT_FOREVER", ONI_TIMEOUT_FOREVER);
  return 0;
}
"#,
        );
        let rust: &[(&str, i64)] = &[
            ("frame", size_of::<OniFrame>() as i64),
            ("frame.data", offset_of!(OniFrame, data) as i64),
            ("frame.timestamp", offset_of!(OniFrame, timestamp) as i64),
            ("frame.frameIndex", offset_of!(OniFrame, frame_index) as i64),
            ("frame.videoMode", offset_of!(OniFrame, video_mode) as i64),
            ("frame.stride", offset_of!(OniFrame, stride) as i64),
            ("videomode", size_of::<OniVideoMode>() as i64),
            ("deviceinfo", size_of::<OniDeviceInfo>() as i64),
            (
                "deviceinfo.usbVendorId",
                offset_of!(OniDeviceInfo, usb_vendor_id) as i64,
            ),
            ("sensorinfo", size_of::<OniSensorInfo>() as i64),
            (
                "sensorinfo.modes",
                offset_of!(OniSensorInfo, supported_video_modes) as i64,
            ),
            ("cropping", size_of::<OniCropping>() as i64),
            ("seek", size_of::<OniSeek>() as i64),
            ("STATUS_NO_DEVICE", STATUS_NO_DEVICE as i64),
            ("STATUS_TIME_OUT", STATUS_TIME_OUT as i64),
            ("SENSOR_DEPTH", SENSOR_DEPTH as i64),
            ("DEPTH_1_MM", PIXEL_FORMAT_DEPTH_1_MM as i64),
            ("DEPTH_100_UM", PIXEL_FORMAT_DEPTH_100_UM as i64),
            ("HFOV", STREAM_PROPERTY_HORIZONTAL_FOV as i64),
            ("VFOV", STREAM_PROPERTY_VERTICAL_FOV as i64),
            ("VIDEO_MODE", STREAM_PROPERTY_VIDEO_MODE as i64),
            ("MAX_VALUE", STREAM_PROPERTY_MAX_VALUE as i64),
            ("NUMBER_OF_FRAMES", STREAM_PROPERTY_NUMBER_OF_FRAMES as i64),
            ("PLAYBACK_SPEED", DEVICE_PROPERTY_PLAYBACK_SPEED as i64),
            ("PLAYBACK_REPEAT", DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED as i64),
            ("API_VERSION", API_VERSION as i64),
            ("TIMEOUT_FOREVER", TIMEOUT_FOREVER as i64),
        ];
        crate::c_probe::assert_matches(&c, rust);
    }
}
