//! Test-only fault injection of `supine run` (the config's `[faults]` table, used by the soak test
//! firmware-app/tests/cli_soak.rs): the service wraps its own source in `supine_drivers::fault::FaultySource` and
//! its link in `supine_drivers::link::FaultyLink`, the wrappers the driver tests use, so that the real service loop
//! (not a copy of it) meets corrupt frames, an unplugged sensor and a stalled link. Garbage from the arm needs no
//! wrapper: the soak's arm peer writes it on the real serial line.
//!
//! Without `[faults]` nothing here is on the frame path. With it, per frame: one comparison, and the wrappers' own
//! cost (a copy of the frame, a few generator draws).

use supine_drivers::fault::{FaultySource, SourceFaultConfig};
use supine_drivers::link::{FaultyLink, Link, LinkFaultConfig};
use supine_drivers::source::DepthSource;
use tracing::warn;

use crate::config::Faults;

/// The service's link: as opened, or inside the fault wrapper.
pub enum ServiceLink {
    /// The link as opened.
    Plain(Box<dyn Link>),
    /// The link inside the fault wrapper (`[faults]`).
    Faulty(FaultyLink<Box<dyn Link>>),
}

impl ServiceLink {
    /// The link to use.
    pub fn get(&mut self) -> &mut dyn Link {
        match self {
            ServiceLink::Plain(l) => l.as_mut(),
            ServiceLink::Faulty(l) => l,
        }
    }
}

/// What `[faults]` asks for, and what has fired so far.
#[derive(Debug)]
pub struct Injector {
    plan: Faults,
    opens: u64,
    unplugged: bool,
    stalled: bool,
}

impl Injector {
    /// An injector for `plan`.
    pub fn new(plan: Faults) -> Self {
        warn!(
            ?plan,
            "[faults] is set: injecting faults into the source and the link (test only)"
        );
        Injector {
            plan,
            opens: 0,
            unplugged: false,
            stalled: false,
        }
    }

    /// Wrap a freshly opened source; `frames` is the count processed so far (the unplug fires once, at
    /// `unplug_at_frame`, whichever open of the source it falls in).
    pub fn source(&mut self, src: Box<dyn DepthSource>, frames: u64) -> Box<dyn DepthSource> {
        self.opens += 1;
        let disconnect_after = match self.plan.unplug_at_frame {
            Some(at) if !self.unplugged => {
                let left = at.saturating_sub(frames);
                // The wrapper counts delivered frames; corrupt ones are not delivered, so the unplug lands on
                // processed frame `at` as the service counts them.
                Some(u32::try_from(left).unwrap_or(u32::MAX))
            }
            _ => None,
        };
        Box::new(FaultySource::new(
            src,
            SourceFaultConfig {
                corrupt_frame: self.plan.corrupt_frames,
                disconnect_after,
                ..SourceFaultConfig::none(self.plan.seed.wrapping_add(self.opens))
            },
        ))
    }

    /// The source failed with a disconnect: the scripted unplug has fired (a later open is healthy).
    pub fn source_failed(&mut self, frames: u64) {
        if self.plan.unplug_at_frame.is_some_and(|at| frames >= at) {
            self.unplugged = true;
        }
    }

    /// Wrap the link.
    pub fn link(&self, link: Box<dyn Link>) -> ServiceLink {
        ServiceLink::Faulty(FaultyLink::new(
            link,
            LinkFaultConfig {
                seed: self.plan.seed,
                ..LinkFaultConfig::default()
            },
        ))
    }

    /// Before processed frame `frames`: start or end the scripted link stall.
    pub fn frame(&mut self, frames: u64, link: &mut ServiceLink) {
        let Some(at) = self.plan.link_stall_at_frame else {
            return;
        };
        let stall = (at..at + self.plan.link_stall_frames).contains(&frames);
        if stall != self.stalled {
            self.stalled = stall;
            if let ServiceLink::Faulty(l) = link {
                l.hold_stall(stall);
            }
            warn!(frame = frames, stalled = stall, "[faults]: link stall");
        }
    }
}
