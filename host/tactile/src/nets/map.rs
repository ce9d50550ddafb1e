//! The plain engine's feature map of one image (channel-last with a zero border) and the
//! per-thread pool its buffers come from and go back to; shared by the direct and the Winograd
//! convolutions.

use faer::Par;
use rayon::prelude::*;

/// Whether `par` runs on the rayon pool (one image's layers) rather than on this thread.
pub(super) fn on_pool(par: Par) -> bool {
    matches!(par, Par::Rayon(_))
}

/// A feature map of one image, channel-last, with a one-pixel zero border and two spare pixels
/// at the end (the last row of the shifted views reads two pixels past the border).
#[derive(Debug, Clone)]
pub(super) struct Map {
    pub(super) h: usize,
    pub(super) w: usize,
    pub(super) c: usize,
    pub(super) data: Vec<f32>,
}

/// Buffers of dropped maps and products on one thread, reused: a full-size image allocates
/// tens of MB per layer, and fresh pages from the system (page faults, zeroing) cost about as
/// much as the arithmetic.
struct Pool<T>(std::cell::RefCell<Vec<Vec<T>>>);

impl<T: Copy + Default> Pool<T> {
    const fn new() -> Self {
        Pool(std::cell::RefCell::new(Vec::new()))
    }

    /// A buffer of `n` values, contents unspecified (every user overwrites it).
    fn take(&self, n: usize) -> Vec<T> {
        let mut v = {
            let mut p = self.0.borrow_mut();
            let best = (0..p.len())
                .filter(|&i| p[i].capacity() >= n)
                .min_by_key(|&i| p[i].capacity())
                .or_else(|| (0..p.len()).max_by_key(|&i| p[i].capacity()));
            best.map(|i| p.swap_remove(i))
        }
        .unwrap_or_default();
        v.resize(n, T::default());
        v
    }

    /// Returns a buffer (at most 16 are kept).
    fn give(&self, v: Vec<T>) {
        let mut p = self.0.borrow_mut();
        if p.len() < 16 {
            p.push(v);
        }
    }
}

thread_local! {
    static POOL: Pool<f32> = const { Pool::new() };
    static POOL_BF16: Pool<u16> = const { Pool::new() };
}

/// A pooled buffer of `n` values, contents unspecified.
pub(super) fn take(n: usize) -> Vec<f32> {
    POOL.with(|p| p.take(n))
}

/// Returns a buffer to the pool.
pub(super) fn give(v: Vec<f32>) {
    POOL.with(|p| p.give(v));
}

/// A pooled buffer of `n` bfloat16 values, contents unspecified.
pub(super) fn take_half(n: usize) -> Vec<u16> {
    POOL_BF16.with(|p| p.take(n))
}

/// Returns a bfloat16 buffer to the pool.
pub(super) fn give_half(v: Vec<u16>) {
    POOL_BF16.with(|p| p.give(v));
}

impl Drop for Map {
    fn drop(&mut self) {
        give(std::mem::take(&mut self.data));
    }
}

impl Map {
    /// A map whose interior is to be written by the caller, who then zeroes the border
    /// ([`Map::zero_border`]).
    pub(super) fn uninit(h: usize, w: usize, c: usize) -> Self {
        Map {
            h,
            w,
            c,
            data: take(((h + 2) * (w + 2) + 2) * c),
        }
    }

    /// Zeroes the border pixels and the two spare ones.
    pub(super) fn zero_border(&mut self) {
        let (pw, c) = (self.w + 2, self.c);
        self.data[..pw * c].fill(0.0);
        for r in 1..=self.h {
            self.data[(r * pw - 1) * c..(r * pw + 1) * c].fill(0.0);
        }
        let n = self.data.len();
        self.data[((self.h + 1) * pw - 1) * c..n].fill(0.0);
    }

    /// Offset of interior pixel (r, col).
    pub(super) fn at(&self, r: usize, col: usize) -> usize {
        ((r + 1) * (self.w + 2) + col + 1) * self.c
    }

    /// From one `[c, h, w]` image.
    pub(super) fn from_chw(x: &[f32], c: usize, h: usize, w: usize, par: Par) -> Self {
        let mut m = Map::uninit(h, w, c);
        m.zero_border();
        m.for_rows(par, |r, row| {
            for (col, px) in row.chunks_exact_mut(c).enumerate() {
                for (ch, v) in px.iter_mut().enumerate() {
                    *v = x[(ch * h + r) * w + col];
                }
            }
        });
        m
    }

    /// Calls `f(r, values)` on the `w c` values of every interior row r, the rows in parallel
    /// on the current pool when `par` is a pool (one image's layers, whose products already
    /// run there; the passes between them were a third of a single image's time).
    pub(super) fn for_rows(&mut self, par: Par, f: impl Fn(usize, &mut [f32]) + Sync + Send) {
        self.map_rows(par, f);
    }

    /// [`Map::for_rows`] collecting what `f` returns per row, in row order.
    pub(super) fn map_rows<T: Send>(
        &mut self,
        par: Par,
        f: impl Fn(usize, &mut [f32]) -> T + Sync + Send,
    ) -> Vec<T> {
        let (h, w, c) = (self.h, self.w, self.c);
        let body = |(r, row): (usize, &mut [f32])| f(r, &mut row[c..(w + 1) * c]);
        let width = (w + 2) * c;
        if on_pool(par) {
            self.data
                .par_chunks_mut(width)
                .skip(1)
                .take(h)
                .enumerate()
                .map(body)
                .collect()
        } else {
            self.data
                .chunks_mut(width)
                .skip(1)
                .take(h)
                .enumerate()
                .map(body)
                .collect()
        }
    }
}
