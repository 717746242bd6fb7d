//! The machine probe: memory bandwidth and arithmetic peaks, the cache, and
//! the work a spring-loop iteration must at least do.

use std::time::Duration;

use bevy::math::Vec4;
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::ClothModel;
use bevy_cloth::solver::Simd;

use super::*;

/// What one core of this machine achieves on simple kernels.
///
/// Each bandwidth is the triad `a = b + s·c` at the fastest of the SIMD
/// levels this CPU runs (the crate's spring pass chooses its level at run
/// time), with its three arrays together half the size of the cache it
/// measures.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// The widest SIMD level this CPU runs, at which
    /// [`Limits::widest_gflops`] is measured.
    pub level: Simd,
    /// The triad over arrays far larger than the caches, GB/s.
    pub memory_gbs: f64,
    /// The triad within the L1 data cache ([`Caches::l1`]), GB/s.
    pub l1_gbs: f64,
    /// The triad past L1, within L2 ([`Caches::l2`]), GB/s.
    pub l2_gbs: f64,
    /// The triad past L2, within the last-level cache, GB/s.
    pub l3_gbs: f64,
    /// The L1 triad in the baseline build's 4-lane code alone, GB/s.
    pub baseline_l1_gbs: f64,
    /// Scalar `f32` multiply–adds, 8 independent chains, GFLOP/s.
    pub scalar_gflops: f64,
    /// 4-lane `Vec4` multiply–adds, 8 independent chains, GFLOP/s: the
    /// baseline build's packed width (SSE2 on x86-64, NEON on aarch64).
    pub simd_gflops: f64,
    /// Fused multiply–adds at [`Limits::level`]'s full width (8 lanes with
    /// AVX2 + FMA, 16 with AVX-512), 8 independent chains, GFLOP/s;
    /// [`Limits::simd_gflops`] when the level is the baseline.
    pub widest_gflops: f64,
    /// The cache sizes the bandwidths were measured within.
    pub caches: Caches,
}

impl Limits {
    /// The bandwidth, GB/s, of where a working set of `bytes` fits.
    pub fn bandwidth_for(&self, bytes: f64) -> f64 {
        let c = &self.caches;
        if bytes <= c.l1 as f64 {
            self.l1_gbs
        } else if bytes <= c.l2 as f64 {
            self.l2_gbs
        } else if bytes <= c.last as f64 {
            self.l3_gbs
        } else {
            self.memory_gbs
        }
    }
}

/// One core's data cache sizes in bytes, from sysfs (48 KiB, 1 MiB and
/// 32 MiB where it does not say).
#[derive(Clone, Copy, Debug)]
pub struct Caches {
    /// L1 data cache.
    pub l1: usize,
    /// L2.
    pub l2: usize,
    /// The last level.
    pub last: usize,
}

impl Caches {
    /// Reads the sizes from `/sys/devices/system/cpu/cpu0/cache`.
    pub fn of_this_cpu() -> Self {
        let read = |i: usize, file: &str| {
            let path = format!("/sys/devices/system/cpu/cpu0/cache/index{i}/{file}");
            std::fs::read_to_string(path)
                .ok()
                .map(|s| s.trim().to_owned())
        };
        let mut caches = Caches {
            l1: 48 << 10,
            l2: 1 << 20,
            last: 32 << 20,
        };
        let mut last_level = 0;
        for i in 0..8 {
            let (Some(level), Some(kind), Some(size)) =
                (read(i, "level"), read(i, "type"), read(i, "size"))
            else {
                continue;
            };
            let (Ok(level), Some(Ok(kib))) = (
                level.parse::<u32>(),
                size.strip_suffix('K').map(str::parse::<usize>),
            ) else {
                continue;
            };
            if kind == "Instruction" {
                continue;
            }
            let bytes = kib << 10;
            match level {
                1 => caches.l1 = bytes,
                2 => caches.l2 = bytes,
                _ => {}
            }
            if level > last_level {
                last_level = level;
                caches.last = bytes;
            }
        }
        caches
    }
}

/// The triad's loop, inlined into a copy per SIMD level (the compiler
/// vectorises each at its level's width).
#[inline(always)]
fn triad_loop(a: &mut [f32], b: &[f32], c: &[f32], s: f32) {
    for ((a, b), c) in a.iter_mut().zip(b).zip(c) {
        *a = b + s * c;
    }
}

#[cfg(target_arch = "x86_64")]
mod wide {
    //! The machine probe's kernels compiled for AVX2 + FMA and AVX-512:
    //! callers check the CPU first ([`Simd::supported`]).
    use std::arch::x86_64::*;

    #[target_feature(enable = "avx2,fma")]
    pub(super) fn triad_avx2(a: &mut [f32], b: &[f32], c: &[f32], s: f32) {
        super::triad_loop(a, b, c, s);
    }

    #[target_feature(enable = "avx512f")]
    pub(super) fn triad_avx512(a: &mut [f32], b: &[f32], c: &[f32], s: f32) {
        super::triad_loop(a, b, c, s);
    }

    /// `rounds` times, 8 independent 8-lane fused multiply–adds.
    #[target_feature(enable = "avx2,fma")]
    pub(super) fn fma_avx2(rounds: usize, m: f32, a: f32) -> f32 {
        let (m, a) = (_mm256_set1_ps(m), _mm256_set1_ps(a));
        let mut acc = [_mm256_set1_ps(1.0); 8];
        for _ in 0..rounds {
            for x in &mut acc {
                *x = _mm256_fmadd_ps(*x, m, a);
            }
        }
        let sum = acc
            .iter()
            .fold(_mm256_setzero_ps(), |s, x| _mm256_add_ps(s, *x));
        _mm256_cvtss_f32(sum)
    }

    /// `rounds` times, 8 independent 16-lane fused multiply–adds.
    #[target_feature(enable = "avx512f")]
    pub(super) fn fma_avx512(rounds: usize, m: f32, a: f32) -> f32 {
        let (m, a) = (_mm512_set1_ps(m), _mm512_set1_ps(a));
        let mut acc = [_mm512_set1_ps(1.0); 8];
        for _ in 0..rounds {
            for x in &mut acc {
                *x = _mm512_fmadd_ps(*x, m, a);
            }
        }
        let sum = acc
            .iter()
            .fold(_mm512_setzero_ps(), |s, x| _mm512_add_ps(s, *x));
        _mm512_reduce_add_ps(sum)
    }
}

/// The triad at `level` (one this CPU runs).
fn triad_at(level: Simd, a: &mut [f32], b: &[f32], c: &[f32], s: f32) {
    match level {
        // SAFETY: the callers pass only levels of `Simd::supported()`, whose
        // features `is_x86_feature_detected!` found on this CPU.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { wide::triad_avx2(a, b, c, s) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { wide::triad_avx512(a, b, c, s) },
        _ => triad_loop(a, b, c, s),
    }
}

fn triad(level: Simd, len: usize, budget: Duration, min_samples: usize) -> f64 {
    let b = vec![1.0f32; len];
    let c = vec![2.0f32; len];
    let mut a = vec![0.0f32; len];
    let s = std::hint::black_box(0.5f32);
    let reps = (1 << 22) / len.max(1) + 1;
    let t = time_runs(budget, min_samples, || {
        for _ in 0..reps {
            triad_at(level, &mut a, &b, &c, s);
            std::hint::black_box(&mut a);
        }
    });
    (12 * len * reps) as f64 / t.median / 1e9
}

/// `x`, hidden from the optimiser in a register of its own, so that eight
/// scalar chains stay scalar (the compiler would otherwise pack them into
/// two `Vec4`s, and the scalar kernel would measure SIMD).
#[inline(always)]
fn opaque(x: f32) -> f32 {
    #[cfg(target_arch = "x86_64")]
    {
        let mut x = x;
        // SAFETY: an empty instruction that reads and writes one register.
        unsafe {
            core::arch::asm!("/* {0} */", inout(xmm_reg) x, options(pure, nomem, nostack));
        }
        x
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::hint::black_box(x)
    }
}

/// Measures [`Limits`].
pub fn limits(config: &PerfConfig) -> Limits {
    const OPS: usize = 1 << 22;
    let scalar = time_runs(config.budget, config.min_samples, || {
        let mut acc = [1.0f32, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7];
        let m = std::hint::black_box(0.999_999f32);
        let a = std::hint::black_box(1e-7f32);
        for _ in 0..OPS / 8 {
            for x in &mut acc {
                *x = opaque(*x * m + a);
            }
        }
        std::hint::black_box(acc);
    });
    let simd = time_runs(config.budget, config.min_samples, || {
        let mut acc = [Vec4::ONE; 8];
        let m = Vec4::splat(std::hint::black_box(0.999_999f32));
        let a = Vec4::splat(std::hint::black_box(1e-7f32));
        for _ in 0..OPS / 8 {
            for x in &mut acc {
                *x = *x * m + a;
            }
        }
        std::hint::black_box(acc);
    });
    let level = Simd::supported().last().copied().unwrap_or(Simd::Baseline);
    let rounds = OPS / 8;
    let (m, a) = (
        std::hint::black_box(0.999_999f32),
        std::hint::black_box(1e-7f32),
    );
    let widest_gflops = match level {
        // SAFETY: `level` is the widest of `Simd::supported()`, so the CPU
        // has its features.
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 | Simd::Avx512 => {
            let lanes = level.lanes();
            let t = time_runs(config.budget, config.min_samples, || {
                let r = if lanes == 16 {
                    unsafe { wide::fma_avx512(rounds, m, a) }
                } else {
                    unsafe { wide::fma_avx2(rounds, m, a) }
                };
                std::hint::black_box(r);
            });
            (2 * lanes * OPS) as f64 / t.median / 1e9
        }
        _ => (2 * 4 * OPS) as f64 / simd.median / 1e9,
    };
    let caches = Caches::of_this_cpu();
    // Three arrays of `f32` filling half of `bytes`.
    let len = |bytes: usize| (bytes / 2 / 12).max(256);
    let levels = Simd::supported();
    let fastest = |len: usize| {
        levels
            .iter()
            .map(|&l| triad(l, len, config.budget, config.min_samples))
            .fold(0.0f64, f64::max)
    };
    Limits {
        level,
        memory_gbs: fastest(config.stream_len),
        l1_gbs: fastest(len(caches.l1)),
        l2_gbs: fastest(len(caches.l2)),
        // Past L2 (four times its size) but well within the last level.
        l3_gbs: fastest(len((8 * caches.l2).min(caches.last)).min(config.stream_len)),
        baseline_l1_gbs: triad(
            Simd::Baseline,
            len(caches.l1),
            config.budget,
            config.min_samples,
        ),
        scalar_gflops: (2 * OPS) as f64 / scalar.median / 1e9,
        simd_gflops: (2 * 4 * OPS) as f64 / simd.median / 1e9,
        widest_gflops,
        caches,
    }
}

/// For a spring-loop method: its iterations per step, and the bytes and
/// flops one iteration must at least move and do, from the counts of its
/// loops (see the page for the per-item model). `None` for the sparse
/// methods, whose work is faer's.
pub fn work_per_iteration(method: &AnyMethod, model: &ClothModel) -> Option<(u32, f64, f64)> {
    let v = model.vertex_count() as f64;
    let s = model.topology().springs().len() as f64;
    // Per iteration: a spring reads its record (16 B), coefficients (8 B)
    // and writes its term (16 B); each of its 2 incidences reads an index
    // (4 B) and the term (16 B); a vertex reads and writes x and the
    // previous iterate and reads its target and 2 scalars (88 B).
    // Flops: 14 per spring (difference, dot, sqrt, divide, scale), 3 per
    // incidence, about 21 per vertex.
    let iteration = (
        40.0 * s + 2.0 * 20.0 * s + 88.0 * v,
        14.0 * s + 6.0 * s + 21.0 * v,
    );
    let iterations = match method {
        AnyMethod::Implicit(c) => c.iterations,
        AnyMethod::Pbd(c) => c.iterations,
        AnyMethod::Symplectic(_) => 1,
        // The methods with sparse solves (and any method added later) have
        // no streaming model here.
        _ => return None,
    };
    Some((iterations, iteration.0, iteration.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caches_are_ordered_and_a_working_set_gets_the_bandwidth_of_where_it_fits() {
        let caches = Caches::of_this_cpu();
        assert!(0 < caches.l1 && caches.l1 < caches.l2 && caches.l2 <= caches.last);
        let limits = Limits {
            level: Simd::Baseline,
            memory_gbs: 1.0,
            l1_gbs: 4.0,
            l2_gbs: 3.0,
            l3_gbs: 2.0,
            baseline_l1_gbs: 4.0,
            scalar_gflops: 1.0,
            simd_gflops: 4.0,
            widest_gflops: 4.0,
            caches: Caches {
                l1: 1 << 10,
                l2: 1 << 20,
                last: 1 << 30,
            },
        };
        for (bytes, gbs) in [
            (1 << 10, 4.0),
            ((1 << 10) + 1, 3.0),
            (1 << 20, 3.0),
            ((1 << 20) + 1, 2.0),
            (1 << 30, 2.0),
            ((1 << 30) + 1, 1.0),
        ] {
            assert_eq!(limits.bandwidth_for(bytes as f64), gbs, "{bytes} B");
        }
    }
}
