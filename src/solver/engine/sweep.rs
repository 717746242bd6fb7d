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
/// and the end.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColouredSprings<'a> {
    pub(crate) ends: &'a [[u32; 2]],
    pub(crate) rest: &'a [f32],
    pub(crate) shares: &'a [[f32; 2]],
    pub(crate) colours: &'a [usize],
}

/// One Gauss–Seidel sweep over `springs` at `level`: each spring moves its
/// ends along `xₐ − x_b` by its shares of `l − L`.
///
/// # Panics
/// If the fields' lengths differ, a colour lies outside them, or an end is
/// not an index of `x`.
pub(crate) fn sweep(level: Simd, springs: ColouredSprings<'_>, x: &mut [Vec3A]) {
    let len = springs.ends.len();
    assert!(springs.rest.len() == len && springs.shares.len() == len);
    assert!(springs.colours.windows(2).all(|c| c[0] <= c[1]));
    assert!(springs.colours.last().is_none_or(|&end| end <= len));
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
            let [a, b] = ends[e].map(|i| i as usize);
            let d = x[a] - x[b];
            let correction = d * factor((d.x * d.x + d.y * d.y) + d.z * d.z, rest[e]);
            x[a] -= shares[e][0] * correction;
            x[b] += shares[e][1] * correction;
        }
    }
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
        let springs = ColouredSprings {
            ends: &ends,
            rest: &rest,
            shares: &shares,
            colours: &colours,
        };
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
        x.clear();
    }
}
