//! The wire protocol between the tracker (head computer) and the arm controller; the written spec is `SPEC.md`
//! next to this file, the CAN database `supine.dbc`.
//!
//! Messages are plain validated structs ([`Message`] = sequence number + capture timestamp + [`Body`]); every
//! encoding has a Packet view over bytes (checked constructors, accessors that cannot panic) and a Repr that is the
//! message itself, in the manner of smoltcp:
//!
//! - [`serial`]: postcard payload + CRC-32C, COBS-framed with `0x00` delimiters; [`stream::SerialDecoder`] takes
//!   bytes in chunks and resynchronises after any damage.
//! - [`can`] / [`can_map`] / [`reassembly`]: classic 8-byte CAN frames, one per signal group, each with an AUTOSAR
//!   E2E-profile-1-style CRC-8 and 4-bit counter; [`reassembly::CanReassembler`] rebuilds messages from groups.
//! - [`slcan`] and [`candump`]: the two text forms of CAN frames that tools and serial CAN adapters speak.
//! - [`consumer`]: the arm-side logic (newest pose, staleness, corruption), shown by `examples/arm_consumer.rs`.
//!
//! Nothing here allocates or reads a clock: buffers are caller-provided or fixed-size, time is an argument.

pub mod can;
pub mod can_map;
pub mod candump;
mod cobs;
pub mod consumer;
pub mod error;
pub mod message;
pub mod reassembly;
pub mod sample;
pub mod serial;
pub mod slcan;
pub mod stream;
pub mod types;

#[cfg(test)]
mod golden;
#[cfg(test)]
mod roundtrip;

pub use error::{DecodeError, EncodeError};
pub use message::{
    ArmState, Body, BodyShape, Command, Health, Kind, Message, ProbeReport, SalientPointReport,
    SalientPoints, TorsoPose,
};
pub use types::{BodyRegion, Confidence, NormalQ14, ShapeMode, Timestamp, TrackerState, UnitQuatQ14};

/// Protocol version carried in every serial frame (first byte) and in every CAN frame's E2E data id.
///
/// Version 1 is the first release. Later versions only append fields, message kinds and enum variants, and a
/// decoder of version N decodes every version up to N; see SPEC.md, "Versioning".
pub const VERSION: u8 = 1;

/// The CAN database describing every frame at the default base id, for cantools, CANalyzer or dbc-codegen.
pub const DBC: &str = include_str!("supine.dbc");
