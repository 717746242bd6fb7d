//! The machine probe: memory bandwidth and arithmetic peaks, the cache, and
//! the work a spring-loop iteration must at least do.

use std::time::Duration;

use bevy::math::Vec4;
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::ClothModel;

use super::*;

/// What one core of this machine achieves on simple kernels.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Triad `a = b + s·c` over arrays far larger than the caches, GB/s.
    pub memory_gbs: f64,
    /// The same triad over arrays that fit in L1/L2 (3 × 16 KiB), GB/s.
    pub cache_gbs: f64,
    /// The same triad over arrays past L2 but within a last-level cache
    /// (3 × 2 MiB), GB/s.
    pub l3_gbs: f64,
    /// Scalar `f32` multiply–adds, 8 independent chains, GFLOP/s.
    pub scalar_gflops: f64,
    /// 4-lane `Vec4` multiply–adds, 8 independent chains, GFLOP/s: the
    /// packed width this crate's build uses (baseline x86-64: SSE2).
    pub simd_gflops: f64,
}

fn triad(len: usize, budget: Duration, min_samples: usize) -> f64 {
    let b = vec![1.0f32; len];
    let c = vec![2.0f32; len];
    let mut a = vec![0.0f32; len];
    let s = std::hint::black_box(0.5f32);
    let reps = (1 << 22) / len.max(1) + 1;
    let t = time_runs(budget, min_samples, || {
        for _ in 0..reps {
            for ((a, b), c) in a.iter_mut().zip(&b).zip(&c) {
                *a = b + s * c;
            }
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
    Limits {
        memory_gbs: triad(config.stream_len, config.budget, config.min_samples),
        cache_gbs: triad(4096, config.budget, config.min_samples),
        l3_gbs: triad(
            (1 << 19).min(config.stream_len),
            config.budget,
            config.min_samples,
        ),
        scalar_gflops: (2 * OPS) as f64 / scalar.median / 1e9,
        simd_gflops: (2 * 4 * OPS) as f64 / simd.median / 1e9,
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
