//! The machine probe: memory bandwidth and arithmetic peaks, the cache, and
//! the work a spring-loop iteration must at least do.

use std::time::Duration;

use bevy::math::Vec4;
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::ClothModel;
use bevy_cloth::solver::simd::Simd;

use super::*;

/// What one core of this machine achieves on simple kernels.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// The widest SIMD level this CPU runs, at which the bandwidths and
    /// [`Limits::widest_gflops`] are measured (the crate's spring pass
    /// picks its level at run time, so its limit is this one's).
    pub level: Simd,
    /// Triad `a = b + s·c` over arrays far larger than the caches, GB/s.
    pub memory_gbs: f64,
    /// The same triad over arrays that fit in L1/L2 (3 × 16 KiB), GB/s.
    pub cache_gbs: f64,
    /// The same triad over arrays past L2 but within a last-level cache
    /// (3 × 2 MiB), GB/s.
    pub l3_gbs: f64,
    /// The L1/L2 triad in the baseline build's 4-lane code, GB/s.
    pub baseline_cache_gbs: f64,
    /// Scalar `f32` multiply–adds, 8 independent chains, GFLOP/s.
    pub scalar_gflops: f64,
    /// 4-lane `Vec4` multiply–adds, 8 independent chains, GFLOP/s: the
    /// baseline build's packed width (SSE2 on x86-64, NEON on aarch64).
    pub simd_gflops: f64,
    /// Fused multiply–adds at [`Limits::level`]'s full width (8 lanes with
    /// AVX2 + FMA, 16 with AVX-512), 8 independent chains, GFLOP/s;
    /// [`Limits::simd_gflops`] when the level is the baseline.
    pub widest_gflops: f64,
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
    Limits {
        level,
        memory_gbs: triad(level, config.stream_len, config.budget, config.min_samples),
        cache_gbs: triad(level, 4096, config.budget, config.min_samples),
        l3_gbs: triad(
            level,
            (1 << 19).min(config.stream_len),
            config.budget,
            config.min_samples,
        ),
        baseline_cache_gbs: triad(Simd::Baseline, 4096, config.budget, config.min_samples),
        scalar_gflops: (2 * OPS) as f64 / scalar.median / 1e9,
        simd_gflops: (2 * 4 * OPS) as f64 / simd.median / 1e9,
        widest_gflops,
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
        AnyMethod::Linear(_) | AnyMethod::Exact(_) | AnyMethod::Projective(_) => return None,
    };
    Some((iterations, iteration.0, iteration.1))
}

/// The last-level cache's size in bytes from sysfs (32 MiB if unknown).
pub(super) fn last_level_cache() -> usize {
    (0..8)
        .rev()
        .find_map(|i| {
            let size = std::fs::read_to_string(format!(
                "/sys/devices/system/cpu/cpu0/cache/index{i}/size"
            ))
            .ok()?;
            let kib: usize = size.trim().strip_suffix('K')?.parse().ok()?;
            Some(kib << 10)
        })
        .unwrap_or(32 << 20)
}
