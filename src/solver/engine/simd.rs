//! The spring pass at the fastest SIMD level this CPU has, chosen at run
//! time.
//!
//! This is the general kernels' spring pass, over any spring list. A grid
//! cloth's implicit iteration runs the stencil kernels instead
//! (`solver::engine::stencil`), whose plain loops the compiler vectorises at each
//! level; [`Simd`] chooses their level too.
//!
//! The crate is built for baseline x86-64 (SSE2) so that a game need not be
//! built with `-C target-cpu=native`; glam's `Vec4` is then four lanes. The
//! spring pass (`spring_products`) also has 8-lane (AVX2) and 16-lane
//! (AVX-512F) versions, compiled with `#[target_feature]` and chosen per call
//! from [`Simd`], against what `is_x86_feature_detected!` reports (it caches
//! its answer).
//!
//! [`Simd::Auto`] (the default) runs AVX2 wherever the CPU has it, also on
//! CPUs with AVX-512, by benchmark (`docs/perf.md`, "SIMD levels", and
//! `docs/measurements.md`): the 16-lane pass spends what it saves on
//! building its registers from 16-byte records, and 16-lane square roots
//! and divisions are no faster per lane than 8-lane ones.
//! [`Simd::Avx512`] runs it on request.
//!
//! Every version does the same IEEE operations in the same order on each
//! spring (`l² = (x² + y²) + z²` without fused multiply–adds, then a
//! correctly rounded square root and division), so **all of them give the
//! same bits** (tested on every path the CPU has): the choice trades speed
//! only, and results do not depend on the machine's instruction set.
//!
//! Why `std::arch` rather than `pulp` (the dispatcher faer is built on):
//! positions are 16-byte `Vec3A` records gathered by spring index, so the
//! pass is a transpose problem — pairs (AVX2) or quadruples (AVX-512) of
//! records are loaded into one register, transposed within each 128-bit lane
//! and the scales broadcast back within the lane. `pulp`'s width-generic
//! `f32s` hides the 128-bit lanes these in-lane shuffles need, so the kernel
//! would have to be written per width anyway. On aarch64 the baseline is
//! NEON (glam's `Vec4`), which has no wider tier to dispatch to.

use bevy::math::Vec3A;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use crate::solver::engine::kernels::{Springs, spring_scales_by};

/// Defines `fn name(level: Simd, args…)` that runs the plain-loop kernel
/// `kernel(args…)` compiled for `level`: the baseline, AVX2 + FMA or
/// AVX-512F (`#[target_feature]` copies, on x86-64), so the compiler
/// vectorises the kernel's loops at that width. `kernel` must be
/// `#[inline(always)]` for its loops to be compiled into each copy.
///
/// Sound by construction: the generated function resolves `level` itself
/// ([`Simd::resolve`], which never names a level the CPU lacks), so no
/// caller can reach a `#[target_feature]` copy on a CPU without it. The
/// `unsafe` it expands to is written here and allowed only inside the
/// generated function; the macro is visible to the engine room alone, so
/// no module outside it holds an expansion.
macro_rules! at_level {
    ($(#[$doc:meta])* $vis:vis fn $name:ident($($arg:ident: $ty:ty),* $(,)?) $(-> $ret:ty)? => $kernel:ident) => {
        $(#[$doc])*
        #[allow(unsafe_code)]
        $vis fn $name(level: $crate::solver::engine::simd::Simd, $($arg: $ty),*) $(-> $ret)? {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx,avx2,fma")]
            fn avx2($($arg: $ty),*) $(-> $ret)? {
                $kernel($($arg),*)
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx,avx2,fma,avx512f")]
            fn avx512($($arg: $ty),*) $(-> $ret)? {
                $kernel($($arg),*)
            }
            match level.resolve() {
                // SAFETY: `Simd::resolve` returns a level only if the CPU
                // has its features.
                #[cfg(target_arch = "x86_64")]
                $crate::solver::engine::simd::Simd::Avx512 => unsafe { avx512($($arg),*) },
                // SAFETY: as above.
                #[cfg(target_arch = "x86_64")]
                $crate::solver::engine::simd::Simd::Avx2 => unsafe { avx2($($arg),*) },
                _ => $kernel($($arg),*),
            }
        }
    };
}
pub(super) use at_level;

/// Which SIMD instruction set the spring pass runs on
/// ([`StepParams::simd`](crate::solver::StepParams::simd)). Every choice gives the
/// same bits (see the [module docs](self)); this only trades speed.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[reflect(Debug, PartialEq, Default)]
pub enum Simd {
    /// The fastest the CPU has, detected at run time (the default): AVX2
    /// where the CPU has it (also on CPUs with AVX-512, by benchmark: see
    /// the module docs), else the baseline.
    #[default]
    Auto,
    /// glam's 4-lane `Vec4`: SSE2 on x86-64, NEON on aarch64.
    Baseline,
    /// 8 lanes: AVX2 (with FMA, the x86-64-v3 level). Runs the baseline
    /// on a CPU without it.
    Avx2,
    /// 16 lanes: AVX-512F. Slower than AVX2 where measured (see the module
    /// docs), so only on request. Runs the widest level below it that the
    /// CPU has on a CPU without it.
    Avx512,
}

impl Simd {
    /// The level that runs for this choice on this CPU: never `Auto`, and
    /// never a level the CPU lacks.
    pub fn resolve(self) -> Simd {
        let widest = Self::widest();
        match self {
            Simd::Auto | Simd::Avx2 if widest == Simd::Avx512 => Simd::Avx2,
            Simd::Auto => widest,
            Simd::Baseline => Simd::Baseline,
            Simd::Avx2 if widest == Simd::Baseline => Simd::Baseline,
            Simd::Avx2 => Simd::Avx2,
            Simd::Avx512 => widest,
        }
    }

    /// Every level this CPU runs, narrowest first (always starting with
    /// [`Simd::Baseline`]): what the report and the tests sweep (hidden
    /// from the docs, as the engine room is).
    #[doc(hidden)]
    pub fn supported() -> Vec<Simd> {
        [Simd::Baseline, Simd::Avx2, Simd::Avx512]
            .into_iter()
            .filter(|s| s.resolve() == *s)
            .collect()
    }

    /// The number of `f32` lanes the level's spring pass works on.
    pub fn lanes(self) -> usize {
        match self.resolve() {
            Simd::Avx512 => 16,
            Simd::Avx2 => 8,
            _ => 4,
        }
    }

    /// A short name for tables and logs (`"sse2"` or `"neon"` for the
    /// baseline, `"avx2"`, `"avx512"`, `"auto"`).
    pub fn name(self) -> &'static str {
        match self {
            Simd::Auto => "auto",
            Simd::Baseline if cfg!(target_arch = "aarch64") => "neon",
            Simd::Baseline => "sse2",
            Simd::Avx2 => "avx2",
            Simd::Avx512 => "avx512",
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn widest() -> Simd {
        if std::arch::is_x86_feature_detected!("avx512f") {
            Simd::Avx512
        } else if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
        {
            Simd::Avx2
        } else {
            Simd::Baseline
        }
    }

    #[cfg(not(target_arch = "x86_64"))]
    fn widest() -> Simd {
        Simd::Baseline
    }
}

/// For every spring `e = (a, b)`, with `d = x_a − x_b` and `l = ‖d‖`:
/// `out[e] = d·(α_e − β_e/l)` (`0` for a spring of zero length), with
/// `[α_e, β_e] = coeffs[e]` — the implicit gradient term `k(1 − L/l)·d`
/// (`α = k`, `β = kL`) or projective dynamics' projection `L/l·d`
/// (`α = 0`, `β = −L`). Runs at `simd`'s level (see the module docs); the
/// springs past the last full group of lanes run the baseline.
///
/// # Panics
/// If `coeffs` or `out` is shorter than `springs`, or `x` has fewer than
/// [`Springs::vertices`] positions.
pub(crate) fn spring_products(
    simd: Simd,
    springs: Springs<'_>,
    coeffs: &[[f32; 2]],
    x: &[Vec3A],
    out: &mut [Vec3A],
) {
    assert!(
        x.len() >= springs.vertices(),
        "{} positions for a cloth of {} vertices",
        x.len(),
        springs.vertices()
    );
    let springs = springs.list();
    let n = springs.len();
    let (coeffs, out) = (&coeffs[..n], &mut out[..n]);
    let done = match simd.resolve() {
        // SAFETY: `resolve` returns a level only if the CPU has its features,
        // and every index of `springs` is below `x.len()` (asserted above).
        #[cfg(target_arch = "x86_64")]
        Simd::Avx512 => unsafe { x86::products_avx512(springs, coeffs, x, out) },
        #[cfg(target_arch = "x86_64")]
        Simd::Avx2 => unsafe { x86::products_avx2(springs, coeffs, x, out) },
        _ => 0,
    };
    let out = &mut out[done..];
    // SAFETY: only the springs' own indices are loaded, each below
    // `x.len()` (asserted above). Unchecked at every level alike: the
    // checks were a quarter of the wide kernels' instructions.
    let load = |v: u32| unsafe { *x.get_unchecked(v as usize) };
    spring_scales_by(&springs[done..], &coeffs[done..], load, |e, d, s| {
        out[e] = d * s;
    });
}

#[cfg(target_arch = "x86_64")]
pub(super) mod x86 {
    //! The wide kernels. Each loads the two ends of its springs' records
    //! into registers holding two (AVX2) or four (AVX-512) springs, one per
    //! 128-bit lane, so that what the baseline does on one spring's `Vec3A`
    //! happens on two or four at once; the lengths are transposed within
    //! the lanes into `x`, `y`, `z` vectors of 8 or 16 springs.

    use std::arch::x86_64::*;

    use bevy::math::Vec3A;

    use crate::model::Spring;

    /// The squared lengths of eight springs held two to a register, spring
    /// `i` in the low lane of `r[i]` and spring `i + 4` in its high lane
    /// (`[d_i | d_{i+4}]`): transposed within the lanes into
    /// `x = [x0 x1 x2 x3 | x4 x5 x6 x7]`, `y`, `z`, then `(x² + y²) + z²`,
    /// the baseline's order without fused multiply–adds. Shared by the
    /// spring pass and XPBD's sweep (`sweep.rs`).
    #[target_feature(enable = "avx,avx2,fma")]
    #[inline]
    pub(in crate::solver::engine) fn lengths_squared(r: &[__m256; 4]) -> __m256 {
        let t0 = _mm256_castps_pd(_mm256_unpacklo_ps(r[0], r[1]));
        let t1 = _mm256_castps_pd(_mm256_unpacklo_ps(r[2], r[3]));
        let t2 = _mm256_castps_pd(_mm256_unpackhi_ps(r[0], r[1]));
        let t3 = _mm256_castps_pd(_mm256_unpackhi_ps(r[2], r[3]));
        let lx = _mm256_castpd_ps(_mm256_unpacklo_pd(t0, t1));
        let ly = _mm256_castpd_ps(_mm256_unpackhi_pd(t0, t1));
        let lz = _mm256_castpd_ps(_mm256_unpacklo_pd(t2, t3));
        _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(lx, lx), _mm256_mul_ps(ly, ly)),
            _mm256_mul_ps(lz, lz),
        )
    }

    /// Eight springs' pairs `[first, second]` (the spring pass's `[α, β]`,
    /// the sweep's shares) as two registers in the lanes' spring order of
    /// [`lengths_squared`]: `[f0 f1 f2 f3 | f4 f5 f6 f7]` and the seconds.
    #[target_feature(enable = "avx,avx2,fma")]
    #[inline]
    pub(in crate::solver::engine) fn split_pairs(pairs: &[[f32; 2]]) -> (__m256, __m256) {
        let pairs: &[[f32; 2]; 8] = pairs[..8].try_into().expect("eight pairs");
        // SAFETY: `pairs[i..i + 2]` is two `[f32; 2]`, 16 readable bytes.
        let load = |i: usize| unsafe { _mm_loadu_ps(pairs[i..i + 2].as_ptr().cast::<f32>()) };
        let c0 = _mm256_set_m128(load(4), load(0));
        let c1 = _mm256_set_m128(load(6), load(2));
        (
            _mm256_shuffle_ps::<0b10_00_10_00>(c0, c1),
            _mm256_shuffle_ps::<0b11_01_11_01>(c0, c1),
        )
    }

    /// The AVX2 pass over the first `springs.len() / 8 * 8` springs;
    /// returns how many it did.
    ///
    /// # Safety
    /// The CPU must have AVX2 and FMA, and every vertex index of `springs`
    /// must be below `x.len()`.
    #[target_feature(enable = "avx,avx2,fma")]
    pub(crate) unsafe fn products_avx2(
        springs: &[Spring],
        coeffs: &[[f32; 2]],
        x: &[Vec3A],
        out: &mut [Vec3A],
    ) -> usize {
        let groups = springs.len() / 8;
        for g in 0..groups {
            let e = 8 * g;
            let s = &springs[e..e + 8];
            let c = &coeffs[e..e + 8];
            // SAFETY: in bounds by the caller's contract.
            let load = |v: usize| -> __m128 { unsafe { *x.get_unchecked(v) }.into() };
            // Springs i (low lane) and i + 4 (high lane): [d_i | d_{i+4}].
            let pair = |i: usize| {
                let a = _mm256_set_m128(load(s[i + 4].a as usize), load(s[i].a as usize));
                let b = _mm256_set_m128(load(s[i + 4].b as usize), load(s[i].b as usize));
                _mm256_sub_ps(a, b)
            };
            let r = [pair(0), pair(1), pair(2), pair(3)];
            let l2 = lengths_squared(&r);
            let (alpha, beta) = split_pairs(c);
            let raw = _mm256_sub_ps(alpha, _mm256_div_ps(beta, _mm256_sqrt_ps(l2)));
            let positive = _mm256_cmp_ps::<_CMP_GT_OQ>(l2, _mm256_setzero_ps());
            let scale = _mm256_and_ps(raw, positive);
            // Each lane's scale broadcast over its own spring's record.
            let p = [
                _mm256_mul_ps(r[0], _mm256_permute_ps::<0x00>(scale)),
                _mm256_mul_ps(r[1], _mm256_permute_ps::<0x55>(scale)),
                _mm256_mul_ps(r[2], _mm256_permute_ps::<0xAA>(scale)),
                _mm256_mul_ps(r[3], _mm256_permute_ps::<0xFF>(scale)),
            ];
            let o = &mut out[e..e + 8];
            for i in 0..4 {
                o[i] = _mm256_castps256_ps128(p[i]).into();
                o[i + 4] = _mm256_extractf128_ps::<1>(p[i]).into();
            }
        }
        groups * 8
    }

    /// The AVX-512 pass over the first `springs.len() / 16 * 16` springs;
    /// returns how many it did.
    ///
    /// Register `r[k]` holds springs `4k .. 4k + 4`, one per 128-bit lane,
    /// so the products are stored as whole registers; after the in-lane
    /// transpose lane `j` holds springs `j, 4 + j, 8 + j, 12 + j`, and the
    /// coefficients are permuted into that order.
    ///
    /// # Safety
    /// The CPU must have AVX-512F, and every vertex index of `springs` must
    /// be below `x.len()`.
    #[target_feature(enable = "avx,avx2,fma,avx512f")]
    pub(crate) unsafe fn products_avx512(
        springs: &[Spring],
        coeffs: &[[f32; 2]],
        x: &[Vec3A],
        out: &mut [Vec3A],
    ) -> usize {
        // Lane j, element m of α (β): spring 4m + j, at 2(4m + j) (+ 1) in
        // the 32 floats of the group's coefficient pairs.
        let mut alpha_idx = [0i32; 16];
        for j in 0..4 {
            for m in 0..4 {
                alpha_idx[4 * j + m] = (2 * (4 * m + j)) as i32;
            }
        }
        // SAFETY: 16 readable `i32`.
        let alpha_idx = unsafe { _mm512_loadu_si512(alpha_idx.as_ptr().cast()) };
        let beta_idx = _mm512_add_epi32(alpha_idx, _mm512_set1_epi32(1));
        let groups = springs.len() / 16;
        for g in 0..groups {
            let e = 16 * g;
            let s = &springs[e..e + 16];
            // SAFETY: in bounds by the caller's contract.
            let load = |v: u32| -> __m128 { unsafe { *x.get_unchecked(v as usize) }.into() };
            // Springs 4k .. 4k + 4, one per lane.
            let four = |k: usize| {
                let s = &s[4 * k..4 * k + 4];
                let half = |i: usize, a: bool| {
                    let v = |t: &Spring| load(if a { t.a } else { t.b });
                    _mm256_set_m128(v(&s[i + 1]), v(&s[i]))
                };
                let join = |a: bool| {
                    _mm512_insertf64x4::<1>(
                        _mm512_castpd256_pd512(_mm256_castps_pd(half(0, a))),
                        _mm256_castps_pd(half(2, a)),
                    )
                };
                _mm512_sub_ps(_mm512_castpd_ps(join(true)), _mm512_castpd_ps(join(false)))
            };
            let r = [four(0), four(1), four(2), four(3)];
            let t0 = _mm512_castps_pd(_mm512_unpacklo_ps(r[0], r[1]));
            let t1 = _mm512_castps_pd(_mm512_unpacklo_ps(r[2], r[3]));
            let t2 = _mm512_castps_pd(_mm512_unpackhi_ps(r[0], r[1]));
            let t3 = _mm512_castps_pd(_mm512_unpackhi_ps(r[2], r[3]));
            let lx = _mm512_castpd_ps(_mm512_unpacklo_pd(t0, t1));
            let ly = _mm512_castpd_ps(_mm512_unpackhi_pd(t0, t1));
            let lz = _mm512_castpd_ps(_mm512_unpacklo_pd(t2, t3));
            // The baseline's order: (x² + y²) + z², no fused multiply–add.
            let l2 = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(lx, lx), _mm512_mul_ps(ly, ly)),
                _mm512_mul_ps(lz, lz),
            );
            let c = coeffs[e..e + 16].as_ptr().cast::<f32>();
            // SAFETY: the group's 16 coefficient pairs are 32 readable floats.
            let (c0, c1) = unsafe { (_mm512_loadu_ps(c), _mm512_loadu_ps(c.add(16))) };
            let alpha = _mm512_permutex2var_ps(c0, alpha_idx, c1);
            let beta = _mm512_permutex2var_ps(c0, beta_idx, c1);
            let raw = _mm512_sub_ps(alpha, _mm512_div_ps(beta, _mm512_sqrt_ps(l2)));
            let positive = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(l2, _mm512_setzero_ps());
            let scale = _mm512_maskz_mov_ps(positive, raw);
            let p = [
                _mm512_mul_ps(r[0], _mm512_permute_ps::<0x00>(scale)),
                _mm512_mul_ps(r[1], _mm512_permute_ps::<0x55>(scale)),
                _mm512_mul_ps(r[2], _mm512_permute_ps::<0xAA>(scale)),
                _mm512_mul_ps(r[3], _mm512_permute_ps::<0xFF>(scale)),
            ];
            let o = &mut out[e..e + 16];
            for (k, p) in p.into_iter().enumerate() {
                // SAFETY: `o[4k .. 4k + 4]` is four `Vec3A`, 64 writable bytes.
                unsafe { _mm512_storeu_ps(o[4 * k..4 * k + 4].as_mut_ptr().cast(), p) };
            }
        }
        groups * 16
    }
}
