//! A per-pixel memo of the observed surface normals that ICP's association computes, valid for one frame.
//!
//! An acquiring tracker frame runs a dozen ICP fits (screening starts, refined starts, a lock refit), each of several
//! iterations over the same torso pixels, and every pair recomputes its pixel's normal from four depth neighbours
//! (four reads, eight divisions, a square root). With a memo lent to the frame ([`crate::depth::DepthFrame::
//! with_normal_memo`]) a pixel's normal is computed once per frame and read back afterwards: the same bits, so every
//! fit gives exactly what it gave without the memo.
//!
//! The memo is the caller's buffer of one [`MemoCell`] per pixel (16 bytes each, 4.9 MB at 640x480), allocated once.
//! A frame stamp marks which cells hold this frame's normals, so a new frame costs nothing but a counter; every
//! 2^32 - 1 frames the cells are cleared once. Cost per lookup: one cell read (16 bytes), one write on a miss.

use core::cell::Cell;

/// One pixel's memoised normal: the frame stamp it was computed for (0: never) and the unit normal, NaN when the
/// pixel has none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MemoCell {
    stamp: u32,
    normal: [f32; 3],
}

impl MemoCell {
    /// A cell that holds nothing.
    pub const EMPTY: MemoCell = MemoCell {
        stamp: 0,
        normal: [0.0; 3],
    };
}

/// The memo of one frame: the caller's cells (one per pixel, row-major), the frame's stamp, and the normal step it
/// serves (normals from neighbours at another distance are computed, not memoised).
#[derive(Clone, Copy)]
pub struct NormalMemo<'m> {
    cells: &'m [Cell<MemoCell>],
    width: u16,
    stamp: u32,
    step_px: u16,
}

impl core::fmt::Debug for NormalMemo<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("NormalMemo")
            .field("cells", &self.cells.len())
            .field("width", &self.width)
            .field("stamp", &self.stamp)
            .field("step_px", &self.step_px)
            .finish()
    }
}

/// The stamps a memo hands out, one per frame: keep one per buffer of cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MemoStamp(u32);

impl MemoStamp {
    /// The memo of the next frame over `cells` (`width` pixels per row) for normals from neighbours `step_px` away.
    /// Every earlier frame's entries become stale; when the stamps run out the cells are cleared once.
    pub fn next<'m>(&mut self, cells: &'m [Cell<MemoCell>], width: u16, step_px: u16) -> NormalMemo<'m> {
        if self.0 == u32::MAX {
            for c in cells {
                c.set(MemoCell::EMPTY);
            }
            self.0 = 0;
        }
        self.0 += 1;
        NormalMemo {
            cells,
            width,
            stamp: self.0,
            step_px,
        }
    }

    /// The memo of the frame [`MemoStamp::next`] last handed out (`None` before the first), to read that frame's
    /// normals again while no newer frame has been stamped.
    pub fn current<'m>(
        &self,
        cells: &'m [Cell<MemoCell>],
        width: u16,
        step_px: u16,
    ) -> Option<NormalMemo<'m>> {
        (self.0 > 0).then_some(NormalMemo {
            cells,
            width,
            stamp: self.0,
            step_px,
        })
    }
}

impl NormalMemo<'_> {
    /// Whether this memo's cells are the pixels of a `width` x `height` frame.
    pub fn fits(&self, width: u16, height: u16) -> bool {
        self.width == width && self.cells.len() == width as usize * height as usize
    }

    /// The distance of the neighbours whose normals it holds, pixels.
    pub fn step_px(&self) -> u16 {
        self.step_px
    }

    /// The normal at pixel (`u`, `v`), computed by `compute` on the first call of this frame (and on every call
    /// for a pixel outside the cells).
    #[inline]
    pub fn get_or(&self, u: i32, v: i32, compute: impl FnOnce() -> Option<[f32; 3]>) -> Option<[f32; 3]> {
        let w = self.width as usize;
        let cell = match (usize::try_from(u), usize::try_from(v)) {
            (Ok(u), Ok(v)) if u < w => v.checked_mul(w).and_then(|r| self.cells.get(r + u)),
            _ => None,
        };
        let Some(cell) = cell else {
            return compute();
        };
        let c = cell.get();
        if c.stamp == self.stamp {
            return (!c.normal[0].is_nan()).then_some(c.normal);
        }
        let n = compute();
        cell.set(MemoCell {
            stamp: self.stamp,
            normal: n.unwrap_or([f32::NAN; 3]),
        });
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_is_computed_once_per_frame_and_again_in_the_next() {
        let mut buf = [MemoCell::EMPTY; 6];
        let cells = Cell::from_mut(&mut buf[..]).as_slice_of_cells();
        let mut stamps = MemoStamp::default();
        let calls = Cell::new(0);
        let count = |n: Option<[f32; 3]>| {
            calls.set(calls.get() + 1);
            n
        };
        let m = stamps.next(cells, 3, 2);
        assert!(m.fits(3, 2) && !m.fits(2, 3) && !m.fits(3, 3));
        assert_eq!(m.step_px(), 2);
        assert_eq!(
            m.get_or(2, 1, || count(Some([0.0, 0.0, -1.0]))),
            Some([0.0, 0.0, -1.0])
        );
        assert_eq!(
            m.get_or(2, 1, || count(Some([1.0, 0.0, 0.0]))),
            Some([0.0, 0.0, -1.0])
        );
        assert_eq!(m.get_or(0, 0, || count(None)), None);
        assert_eq!(
            m.get_or(0, 0, || count(Some([1.0, 0.0, 0.0]))),
            None,
            "a pixel without a normal is memoised too"
        );
        assert_eq!(calls.get(), 2);
        let m = stamps.next(cells, 3, 2);
        assert_eq!(
            m.get_or(2, 1, || count(Some([1.0, 0.0, 0.0]))),
            Some([1.0, 0.0, 0.0])
        );
        assert_eq!(calls.get(), 3);
        // Outside the cells (below, left, above, right of them): computed every time, never another pixel's.
        for (u, v) in [(0, 5), (-1, 0), (0, -1), (3, 0)] {
            assert_eq!(m.get_or(u, v, || count(None)), None);
        }
        assert_eq!(calls.get(), 7);
    }

    #[test]
    fn the_current_memo_reads_the_last_frames_normals_until_the_next_frame() {
        let mut buf = [MemoCell::EMPTY; 4];
        let cells = Cell::from_mut(&mut buf[..]).as_slice_of_cells();
        let mut stamps = MemoStamp::default();
        assert!(stamps.current(cells, 2, 2).is_none());
        let m = stamps.next(cells, 2, 2);
        assert_eq!(m.get_or(1, 0, || Some([0.0, 1.0, 0.0])), Some([0.0, 1.0, 0.0]));
        let again = stamps.current(cells, 2, 2).unwrap();
        assert_eq!(again.get_or(1, 0, || None), Some([0.0, 1.0, 0.0]));
        let _ = stamps.next(cells, 2, 2);
        let stale = stamps.current(cells, 2, 2).unwrap();
        assert_eq!(
            stale.get_or(1, 0, || None),
            None,
            "the next frame's memo does not read it"
        );
    }

    #[test]
    fn the_stamps_clear_the_cells_when_they_run_out() {
        let mut buf = [MemoCell::EMPTY; 4];
        let cells = Cell::from_mut(&mut buf[..]).as_slice_of_cells();
        let mut stamps = MemoStamp::default();
        let m = stamps.next(cells, 2, 2);
        assert_eq!(m.stamp, 1);
        assert_eq!(m.get_or(1, 1, || Some([0.0, 1.0, 0.0])), Some([0.0, 1.0, 0.0]));
        stamps.0 = u32::MAX - 1;
        assert_eq!(stamps.next(cells, 2, 2).stamp, u32::MAX);
        // Stamp 1 again after the wrap: the cell written under stamp 1 long ago must not read as this frame's.
        let m = stamps.next(cells, 2, 2);
        assert_eq!(m.stamp, 1);
        assert_eq!(m.get_or(1, 1, || Some([1.0, 0.0, 0.0])), Some([1.0, 0.0, 0.0]));
        assert_eq!(m.get_or(1, 1, || None), Some([1.0, 0.0, 0.0]));
    }
}
