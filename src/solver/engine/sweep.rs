//! XPBD's Gauss–Seidel sweep over coloured springs, at the step's SIMD
//! level (`at_level!`): within a colour, springs share no vertex, so a
//! batch of them reads all its ends, computes its square roots and
//! divisions as one vector operation, then writes its ends. The same bits
//! at every level (the same IEEE operations per spring, no fused
//! multiply–adds).

use bevy::math::Vec3A;

use super::simd::{Simd, at_level};

/// Springs per batch: two AVX2 registers of lengths.
const BATCH: usize = 16;

/// The springs of a sweep, in colour order, by field (see
/// `solver::xpbd`): `ends[e]`, `rest[e]` and `shares[e]` (the share of
/// the violation each end takes); `colours` are where each colour starts,
/// and the end. Checked once when made ([`ColouredSprings::new`]), so the
/// sweeps of a step's substeps do not check them again.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColouredSprings<'a> {
    ends: &'a [[u32; 2]],
    rest: &'a [f32],
    shares: &'a [[f32; 2]],
    colours: &'a [usize],
    /// Every end is below this.
    vertices: usize,
}

impl<'a> ColouredSprings<'a> {
    /// The springs of `vertices` vertices.
    ///
    /// # Panics
    /// If the fields' lengths differ, the colours do not rise within them,
    /// or an end is not below `vertices`.
    pub(crate) fn new(
        ends: &'a [[u32; 2]],
        rest: &'a [f32],
        shares: &'a [[f32; 2]],
        colours: &'a [usize],
        vertices: usize,
    ) -> Self {
        let len = ends.len();
        assert!(rest.len() == len && shares.len() == len);
        assert!(colours.windows(2).all(|c| c[0] <= c[1]));
        assert!(colours.last().is_none_or(|&end| end <= len));
        assert!(
            ends.iter().flatten().all(|&v| (v as usize) < vertices),
            "a spring end past the {vertices} vertices"
        );
        Self {
            ends,
            rest,
            shares,
            colours,
            vertices,
        }
    }
}

/// One Gauss–Seidel sweep over `springs` at `level`: each spring moves its
/// ends along `xₐ − x_b` by its shares of `l − L`.
///
/// # Panics
/// If the fields' lengths differ, a colour lies outside them, or an end is
/// not an index of `x`.
pub(crate) fn sweep(level: Simd, springs: ColouredSprings<'_>, x: &mut [Vec3A]) {
    assert!(
        x.len() >= springs.vertices,
        "{} positions for {} vertices",
        x.len(),
        springs.vertices
    );
    #[cfg(target_arch = "x86_64")]
    if level.resolve() != Simd::Baseline {
        for colour in springs.colours.windows(2) {
            // SAFETY: the CPU has AVX2 (`resolve` never names a level it
            // lacks, and AVX-512 CPUs have AVX2), every end is an index of
            // `x` (below `vertices`, checked when the springs were made,
            // and `vertices ≤ x.len()`, asserted above), and the colours
            // lie within the fields (checked when made).
            let done = unsafe { x86::batches_avx2(springs, (colour[0], colour[1]), x) };
            for e in done..colour[1] {
                one_spring(&springs, e, x);
            }
        }
        return;
    }
    sweep_at(level, springs, x);
}

at_level! {
    /// [`sweep_kernel`] at `level`.
    fn sweep_at(springs: ColouredSprings<'_>, x: &mut [Vec3A]) => sweep_kernel
}

#[inline(always)]
fn sweep_kernel(springs: ColouredSprings<'_>, x: &mut [Vec3A]) {
    let ColouredSprings {
        ends,
        rest,
        shares,
        colours,
        ..
    } = springs;
    for colour in colours.windows(2) {
        let (start, end) = (colour[0], colour[1]);
        let mut at = start;
        while at + BATCH <= end {
            let ends: &[[u32; 2]; BATCH] = ends[at..at + BATCH].try_into().unwrap();
            let rest: &[f32; BATCH] = rest[at..at + BATCH].try_into().unwrap();
            let shares: &[[f32; 2]; BATCH] = shares[at..at + BATCH].try_into().unwrap();
            let mut d = [Vec3A::ZERO; BATCH];
            let mut scale = [0.0f32; BATCH];
            for j in 0..BATCH {
                d[j] = x[ends[j][0] as usize] - x[ends[j][1] as usize];
                scale[j] = (d[j].x * d[j].x + d[j].y * d[j].y) + d[j].z * d[j].z;
            }
            for j in 0..BATCH {
                scale[j] = factor(scale[j], rest[j]);
            }
            for j in 0..BATCH {
                let correction = d[j] * scale[j];
                x[ends[j][0] as usize] -= shares[j][0] * correction;
                x[ends[j][1] as usize] += shares[j][1] * correction;
            }
            at += BATCH;
        }
        for e in at..end {
            one_spring(&springs, e, x);
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod x86 {
    //! The AVX2 sweep: eight springs of a colour at a time, two per
    //! register (one per 128-bit lane), their lengths transposed within
    //! the lanes into `x`, `y`, `z` vectors (as the spring pass in
    //! `simd.rs`), so the gathers and scatters move whole 16-byte records
    //! and the arithmetic runs eight springs wide. The same IEEE operations
    //! per spring as [`sweep_kernel`](super::sweep_kernel): the same bits.

    use std::arch::x86_64::*;

    use bevy::math::Vec3A;

    use super::ColouredSprings;
    use crate::solver::engine::simd::x86::{lengths_squared, split_pairs};

    /// The full batches of eight of the springs `start..end` (one colour)
    /// at AVX2; returns where they end (the rest are left to the caller).
    ///
    /// # Safety
    /// The CPU must have AVX2, every end in `start..end` must be an index
    /// of `x`, and `start..end` must lie within the fields.
    #[target_feature(enable = "avx,avx2,fma")]
    pub(super) unsafe fn batches_avx2(
        springs: ColouredSprings<'_>,
        (start, end): (usize, usize),
        x: &mut [Vec3A],
    ) -> usize {
        let ColouredSprings {
            ends, rest, shares, ..
        } = springs;
        let p = x.as_mut_ptr();
        // SAFETY (every access below): `v` is an end, an index of `x`.
        let load = |v: u32| -> __m128 { unsafe { *p.add(v as usize) }.into() };
        let store = |v: u32, value: __m128| unsafe { *p.add(v as usize) = value.into() };
        let mut at = start;
        while at + 8 <= end {
            let e = &ends[at..at + 8];
            // Springs i (low lane) and i + 4 (high lane): [d_i | d_{i+4}].
            let pair = |i: usize| {
                let a = _mm256_set_m128(load(e[i + 4][0]), load(e[i][0]));
                let b = _mm256_set_m128(load(e[i + 4][1]), load(e[i][1]));
                _mm256_sub_ps(a, b)
            };
            let r = [pair(0), pair(1), pair(2), pair(3)];
            let l2 = lengths_squared(&r);
            // SAFETY: `rest[at..at + 8]` is eight readable floats.
            let rest = unsafe { _mm256_loadu_ps(rest[at..at + 8].as_ptr()) };
            let l = _mm256_sqrt_ps(l2);
            let raw = _mm256_div_ps(_mm256_sub_ps(l, rest), l);
            let positive = _mm256_cmp_ps::<_CMP_GT_OQ>(l2, _mm256_setzero_ps());
            let scale = _mm256_and_ps(raw, positive);
            let (share_a, share_b) = split_pairs(&shares[at..at + 8]);
            // Lane i's value over its own spring's record.
            let broadcast = |v: __m256| {
                [
                    _mm256_permute_ps::<0x00>(v),
                    _mm256_permute_ps::<0x55>(v),
                    _mm256_permute_ps::<0xAA>(v),
                    _mm256_permute_ps::<0xFF>(v),
                ]
            };
            let (scale, share_a, share_b) =
                (broadcast(scale), broadcast(share_a), broadcast(share_b));
            for i in 0..4 {
                let correction = _mm256_mul_ps(r[i], scale[i]);
                let to_a = _mm256_mul_ps(share_a[i], correction);
                let to_b = _mm256_mul_ps(share_b[i], correction);
                let halves = [
                    (
                        i,
                        _mm256_castps256_ps128(to_a),
                        _mm256_castps256_ps128(to_b),
                    ),
                    (
                        i + 4,
                        _mm256_extractf128_ps::<1>(to_a),
                        _mm256_extractf128_ps::<1>(to_b),
                    ),
                ];
                for (spring, da, db) in halves {
                    let [a, b] = e[spring];
                    store(a, _mm_sub_ps(load(a), da));
                    store(b, _mm_add_ps(load(b), db));
                }
            }
            at += 8;
        }
        at
    }
}

/// One spring of the sweep, alone (what a colour's batches leave).
#[inline(always)]
fn one_spring(springs: &ColouredSprings<'_>, e: usize, x: &mut [Vec3A]) {
    let [a, b] = springs.ends[e].map(|i| i as usize);
    let d = x[a] - x[b];
    let correction = d * factor((d.x * d.x + d.y * d.y) + d.z * d.z, springs.rest[e]);
    x[a] -= springs.shares[e][0] * correction;
    x[b] += springs.shares[e][1] * correction;
}

/// `(l − L)/l` for `l = √l²`; 0 for a spring of zero length (whose
/// direction is unknown: it waits for its ends to part).
#[inline(always)]
fn factor(length_squared: f32, rest: f32) -> f32 {
    let l = length_squared.sqrt();
    let scale = (l - rest) / l;
    if length_squared > 0.0 { scale } else { 0.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_level_gives_the_same_bits_as_one_spring_at_a_time() {
        // Two colours of a chain of 41 vertices (odd and even links), so
        // both colours have full batches and a remainder.
        let n = 41;
        let mut x: Vec<Vec3A> = (0..n)
            .map(|i| Vec3A::new(i as f32 * 0.31, (i as f32 * 0.7).sin(), 0.1 * i as f32))
            .collect();
        x[7] = x[8]; // A spring of zero length.
        let mut ends = vec![];
        for parity in 0..2 {
            ends.extend((parity..n - 1).step_by(2).map(|i| [i as u32, i as u32 + 1]));
        }
        let rest: Vec<f32> = (0..ends.len()).map(|e| 0.2 + 0.01 * e as f32).collect();
        let shares: Vec<[f32; 2]> = (0..ends.len())
            .map(|e| [0.5, 0.25 + 0.01 * e as f32])
            .collect();
        let colours = [0, n / 2, ends.len()];
        let springs = ColouredSprings::new(&ends, &rest, &shares, &colours, n);
        let mut serial = x.clone();
        for e in 0..ends.len() {
            let [a, b] = ends[e].map(|i| i as usize);
            let d = serial[a] - serial[b];
            let l = d.length();
            if l > 0.0 {
                let c = d * ((l - rest[e]) / l);
                serial[a] -= shares[e][0] * c;
                serial[b] += shares[e][1] * c;
            }
        }
        for level in Simd::supported() {
            let mut y = x.clone();
            sweep(level, springs, &mut y);
            assert_eq!(y, serial, "{level:?}");
        }
        assert!(x.iter().zip(&serial).any(|(a, b)| a != b));
    }

    #[test]
    #[should_panic(expected = "a spring end past the 3 vertices")]
    fn springs_with_an_end_past_the_vertices_are_refused() {
        let _ = ColouredSprings::new(&[[0, 3]], &[1.0], &[[0.5, 0.5]], &[0, 1], 3);
    }

    #[test]
    #[should_panic(expected = "2 positions for 3 vertices")]
    fn too_few_positions_are_refused() {
        let springs = ColouredSprings::new(&[[0, 2]], &[1.0], &[[0.5, 0.5]], &[0, 1], 3);
        sweep(Simd::Auto, springs, &mut [Vec3A::ZERO; 2]);
    }
}
