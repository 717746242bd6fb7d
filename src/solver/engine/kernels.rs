//! The hot loops the spring-based methods share: the packed-SIMD spring
//! pass and the fixed-chunk (optionally parallel) loops.

use core::ops::{Add, Mul, Sub};

use bevy::math::{Mat4, Vec3A, Vec4};

use crate::model::{Adjacency, ClothModel, Spring};

/// Vertices (or springs) per chunk of the chunked loops. Fixed, so that
/// reductions over chunks give the same bits whatever the thread count.
pub(crate) const CHUNK: usize = 4096;

/// Below this many elements the chunked loops run serially: a task per
/// chunk costs more than it saves.
pub const PARALLEL_MIN: usize = 32_768;

pub(crate) fn parallel_pool(
    parallel: bool,
    len: usize,
) -> Option<&'static bevy::tasks::ComputeTaskPool> {
    if parallel && len >= PARALLEL_MIN {
        bevy::tasks::ComputeTaskPool::try_get().filter(|p| p.thread_num() > 1)
    } else {
        None
    }
}

/// Runs `f(start, chunk)` over `CHUNK`-sized chunks of `data`, on Bevy's
/// `ComputeTaskPool` when `parallel` is set (from
/// [`StepParams::parallel`](super::StepParams::parallel)), `data` has at
/// least [`PARALLEL_MIN`] elements and
/// the pool (set up by Bevy's `TaskPoolPlugin`) has more than one thread,
/// else serially. The chunks are the same either way, and each element is
/// written by exactly one call, so the result is bitwise the same.
pub(crate) fn for_chunks<T: Send>(
    parallel: bool,
    data: &mut [T],
    f: impl Fn(usize, &mut [T]) + Send + Sync,
) {
    match parallel_pool(parallel, data.len()) {
        Some(pool) => {
            let f = &f;
            pool.scope(|scope| {
                for (i, chunk) in data.chunks_mut(CHUNK).enumerate() {
                    scope.spawn(async move { f(i * CHUNK, chunk) });
                }
            });
        }
        None => {
            for (i, chunk) in data.chunks_mut(CHUNK).enumerate() {
                f(i * CHUNK, chunk);
            }
        }
    }
}

/// [`for_chunks`] over two slices of the same length, chunked alike;
/// `f(start, a, b)` returns a value per chunk, written to `results[chunk]`
/// (so reductions can add them in chunk order).
pub(crate) fn for_chunks2<A: Send, B: Send, R: Send + Copy + Default>(
    parallel: bool,
    a: &mut [A],
    b: &mut [B],
    results: &mut Vec<R>,
    f: impl Fn(usize, &mut [A], &mut [B]) -> R + Send + Sync,
) {
    let chunks = a.len().div_ceil(CHUNK);
    results.clear();
    results.resize(chunks, R::default());
    let pool = parallel_pool(parallel, a.len());
    let work = a
        .chunks_mut(CHUNK)
        .zip(b.chunks_mut(CHUNK))
        .zip(results.iter_mut())
        .enumerate();
    match pool {
        Some(pool) => {
            let f = &f;
            pool.scope(|scope| {
                for (i, ((a, b), r)) in work {
                    scope.spawn(async move {
                        *r = f(i * CHUNK, a, b);
                    });
                }
            });
        }
        None => {
            for (i, ((a, b), r)) in work {
                *r = f(i * CHUNK, a, b);
            }
        }
    }
}

/// For every spring `e = (a, b)` of `springs`, with `d = x_a − x_b` and
/// `l = ‖d‖`: calls `emit(e, d, α_e − β_e/l)` (`0` for a spring of zero
/// length, whose direction is undefined), with `[α_e, β_e] = coeffs[e]`.
///
/// Both spring-based pipelines have this form: the implicit gradient term is
/// `d·k(1 − L/l)` (`α = k`, `β = kL`), and PBD's half correction is
/// `d·L/(2l)` (`α = 0`, `β = −L/2`). `e` counts from 0 within `springs`.
///
/// Four springs at a time (see [`spring_groups`]), so the square roots and
/// the divisions are one packed SIMD instruction each for the four. Per
/// spring, a horizontal dot product and a scalar `sqrtss` + `divss` bounded
/// the loop before; on the lab cloth this halves the spring pass (see
/// `docs/perf.md`).
#[inline]
pub(crate) fn spring_scales(
    springs: &[Spring],
    coeffs: &[[f32; 2]],
    x: &[Vec3A],
    emit: impl FnMut(usize, Vec3A, f32),
) {
    spring_scales_by(springs, coeffs, |v| x[v as usize], emit);
}

/// [`spring_scales`] with the positions read by `load(vertex)`.
#[inline(always)]
pub(crate) fn spring_scales_by(
    springs: &[Spring],
    coeffs: &[[f32; 2]],
    load: impl Fn(u32) -> Vec3A,
    mut emit: impl FnMut(usize, Vec3A, f32),
) {
    spring_groups_by(springs, &load, |e, d, l2| {
        let c = &coeffs[e..e + 4];
        let alpha = Vec4::new(c[0][0], c[1][0], c[2][0], c[3][0]);
        let beta = Vec4::new(c[0][1], c[1][1], c[2][1], c[3][1]);
        let scale = Vec4::select(l2.cmpgt(Vec4::ZERO), alpha - beta / l2.sqrt(), Vec4::ZERO);
        emit(e, d[0], scale.x);
        emit(e + 1, d[1], scale.y);
        emit(e + 2, d[2], scale.z);
        emit(e + 3, d[3], scale.w);
    });
    let done = springs.len() / 4 * 4;
    for (j, (s, [alpha, beta])) in springs[done..].iter().zip(&coeffs[done..]).enumerate() {
        let d = load(s.a) - load(s.b);
        let l2 = d.length_squared();
        let scale = if l2 > 0.0 {
            alpha - beta / l2.sqrt()
        } else {
            0.0
        };
        emit(done + j, d, scale);
    }
}

/// Calls `group(e, d, l²)` for the springs `e .. e + 4` of `springs`, four
/// at a time (the last `len % 4` springs are left to the caller, from
/// `len / 4 * 4`): their four `d = x_a − x_b` and, packed, their squared
/// lengths. The four `d` are transposed in registers (glam's `Mat4`) into
/// `x`, `y` and `z` lanes, so what follows on the lengths is packed SIMD
/// (glam's `Vec4`: SSE2 on x86-64, NEON on aarch64).
#[inline(always)]
pub(crate) fn spring_groups(
    springs: &[Spring],
    x: &[Vec3A],
    group: impl FnMut(usize, &[Vec3A; 4], Vec4),
) {
    spring_groups_by(springs, |v| x[v as usize], group);
}

/// [`spring_groups`] with the positions read by `load(vertex)`.
#[inline(always)]
fn spring_groups_by(
    springs: &[Spring],
    load: impl Fn(u32) -> Vec3A,
    mut group: impl FnMut(usize, &[Vec3A; 4], Vec4),
) {
    for (g, s) in springs.chunks_exact(4).enumerate() {
        let d = [
            load(s[0].a) - load(s[0].b),
            load(s[1].a) - load(s[1].b),
            load(s[2].a) - load(s[2].b),
            load(s[3].a) - load(s[3].b),
        ];
        let lanes = Mat4::from_cols(
            d[0].extend(0.0),
            d[1].extend(0.0),
            d[2].extend(0.0),
            d[3].extend(0.0),
        )
        .transpose();
        let l2 =
            lanes.x_axis * lanes.x_axis + lanes.y_axis * lanes.y_axis + lanes.z_axis * lanes.z_axis;
        group(4 * g, &d, l2);
    }
}

/// Springs of a model (all or a range of them) with a bound that each of
/// their vertex indices is below: what lets the spring pass read the
/// positions without a bounds check per index.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Springs<'a> {
    list: &'a [Spring],
    vertices: usize,
}

impl<'a> Springs<'a> {
    /// The model's springs: its topology checked every index against its
    /// vertex count when it was built.
    pub(crate) fn of(model: &'a ClothModel) -> Self {
        Self {
            list: model.topology().springs(),
            vertices: model.vertex_count(),
        }
    }

    /// The springs `range` of these.
    pub(crate) fn range(self, range: std::ops::Range<usize>) -> Self {
        Self {
            list: &self.list[range],
            vertices: self.vertices,
        }
    }

    /// The springs.
    pub(crate) fn list(self) -> &'a [Spring] {
        self.list
    }

    /// Every vertex index of [`Springs::list`] is below this.
    pub(crate) fn vertices(self) -> usize {
        self.vertices
    }
}

/// [`spring_scales`] over a model's springs, with each spring's two end
/// positions given to `emit(e, d, scale, x_a, x_b)` too. The positions are
/// read without a bounds check per index: [`Springs`] bounds every index,
/// and `x` is checked against that bound once.
///
/// # Panics
/// If `x` has fewer than [`Springs::vertices`] positions, or `coeffs` fewer
/// entries than the springs.
#[inline(always)]
pub(crate) fn spring_scales_ends(
    springs: Springs<'_>,
    coeffs: &[[f32; 2]],
    x: &[Vec3A],
    mut emit: impl FnMut(usize, Vec3A, f32, Vec3A, Vec3A),
) {
    assert!(x.len() >= springs.vertices());
    let list = springs.list();
    let coeffs = &coeffs[..list.len()];
    // SAFETY: every index of `list` is below `springs.vertices()`
    // (`Springs`' invariant), and so below `x.len()` (asserted above).
    let load = |v: u32| unsafe { *x.get_unchecked(v as usize) };
    spring_scales_by(list, coeffs, load, |e, d, scale| {
        let s = &list[e];
        emit(e, d, scale, load(s.a), load(s.b));
    });
}

/// A cloth's padded rows (see
/// [`Adjacency::padded`](crate::model::Adjacency::padded)) as byte offsets
/// into per-spring items of one type, each index checked against the item
/// count when the rows were filled: what lets [`RowGather`] read the items
/// without a bounds check per index (the eight checks were a quarter of
/// the instructions of the lab's vertex pass, which is bound by
/// instructions).
#[derive(Clone, Debug, Default)]
pub(crate) struct PaddedRows {
    rows: Vec<[[u32; 4]; 2]>,
    /// Every offset is `item_bytes·e` for an `e` below this.
    items: usize,
    item_bytes: usize,
    /// The adjacency the rows were taken from (its id), if any.
    source: Option<u64>,
}

impl PaddedRows {
    /// Takes `adjacency`'s padded rows for items of type `T`, `items` of
    /// them (a padded row holds spring indices and the pad `springs.len()`,
    /// so one item per spring and one more for the pad), unless they are
    /// already these. Leaves the rows empty when the adjacency has none, or
    /// when an offset would not fit in `u32` (such a cloth runs the
    /// unpadded gathers).
    ///
    /// # Panics
    /// If an index of the rows is not below `items`.
    pub(crate) fn update<T>(&mut self, adjacency: &Adjacency, items: usize) {
        let bytes = std::mem::size_of::<T>();
        if self.source == Some(adjacency.id()) && (self.items, self.item_bytes) == (items, bytes) {
            return;
        }
        self.rows.clear();
        (self.items, self.item_bytes) = (items, bytes);
        self.source = Some(adjacency.id());
        let Some(rows) = adjacency.padded() else {
            return;
        };
        if items > (u32::MAX as usize) / bytes {
            return;
        }
        let max = rows.iter().flatten().flatten().copied().max().unwrap_or(0);
        assert!(
            rows.is_empty() || (max as usize) < items,
            "padded row index {max} for {items} items"
        );
        let b = bytes as u32;
        self.rows
            .extend(rows.iter().map(|r| r.map(|side| side.map(|e| e * b))));
    }

    /// True when there are no rows.
    pub(crate) fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// How many rows.
    pub(crate) fn len(&self) -> usize {
        self.rows.len()
    }

    /// The gathers of rows `range` over `items`.
    ///
    /// # Panics
    /// If `items` is shorter than the count the rows were checked against,
    /// or is of another type's size.
    pub(crate) fn gather<'a, T>(
        &'a self,
        range: std::ops::Range<usize>,
        items: &'a [T],
    ) -> RowGather<'a, T> {
        assert!(items.len() >= self.items && std::mem::size_of::<T>() == self.item_bytes);
        RowGather {
            rows: &self.rows[range],
            items,
        }
    }
}

/// Gathers over some of a [`PaddedRows`]' rows, each row's items read
/// without a bounds check per index.
#[derive(Clone, Copy)]
pub(crate) struct RowGather<'a, T> {
    rows: &'a [[[u32; 4]; 2]],
    items: &'a [T],
}

impl<T> RowGather<'_, T> {
    /// The first `n` rows of these (so a loop over `0..n` needs no bounds
    /// checks).
    ///
    /// # Panics
    /// If there are fewer than `n` rows.
    #[inline(always)]
    pub(crate) fn first(self, n: usize) -> Self {
        Self {
            rows: &self.rows[..n],
            items: self.items,
        }
    }

    /// The two sums of row `j` (counted within the gather's range):
    /// `start(item)` over its start springs and `end(item)` over its end
    /// springs, each summed as a tree (short chains of additions).
    #[inline(always)]
    pub(crate) fn sums(
        &self,
        j: usize,
        start: impl Fn(&T) -> Vec3A,
        end: impl Fn(&T) -> Vec3A,
    ) -> (Vec3A, Vec3A) {
        let [p, m] = &self.rows[j];
        let base = self.items.as_ptr().cast::<u8>();
        // SAFETY: every offset of the rows is `size_of::<T>()·e` for an `e`
        // below the checked item count (`PaddedRows::fill`), and `items`
        // has at least that many (`PaddedRows::gather`); aligned, as the
        // items are.
        let item = |b: u32| unsafe { &*base.add(b as usize).cast::<T>() };
        let (a, b) = (|o| start(item(o)), |o| end(item(o)));
        (
            (a(p[0]) + a(p[1])) + (a(p[2]) + a(p[3])),
            (b(m[0]) + b(m[1])) + (b(m[2]) + b(m[3])),
        )
    }
}

/// `a·b` with four running sums (one sum would wait on each add's latency).
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut sums = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(a, b)| a * b)
        .sum();
    for (a, b) in ca.zip(cb) {
        for l in 0..4 {
            sums[l] += a[l] * b[l];
        }
    }
    sums.iter().sum::<f64>() + tail
}

/// Chebyshev's blend of an update `x̂` with the iterate before last
/// (`solver::chebyshev`):
/// `ω(x̂ − before) + before` (the same operations, in this order, on every
/// path: a vertex, a lane of the grid kernels, a projective iterate).
#[inline(always)]
pub(crate) fn blend<T>(omega: f32, x_hat: T, before: T) -> T
where
    T: Copy + Add<Output = T> + Sub<Output = T>,
    f32: Mul<T, Output = T>,
{
    omega * (x_hat - before) + before
}

#[cfg(test)]
mod tests {
    use bevy::math::Affine3A;

    use super::*;
    use crate::model::{ClothBuilder, ClothState};
    use crate::testing::noise;

    /// The lab cloth and its padded rows (one item per spring and the
    /// pad's).
    fn lab_rows() -> (ClothModel, Vec<[[u32; 4]; 2]>) {
        let model = ClothBuilder::lab().build().unwrap();
        let rows = model.topology().adjacency().padded().unwrap().to_vec();
        (model, rows)
    }

    #[test]
    fn padded_gathers_sum_each_rows_items_as_the_plain_loop_does() {
        let (model, rows) = lab_rows();
        let springs = model.topology().springs().len();
        let mut seed = 3;
        let mut items: Vec<Vec3A> = (0..springs).map(|_| noise(&mut seed)).collect();
        items.push(Vec3A::ZERO);
        let mut padded = PaddedRows::default();
        padded.update::<Vec3A>(model.topology().adjacency(), springs + 1);
        assert_eq!(padded.len(), rows.len());
        let gather = padded.gather(0..rows.len(), &items[..]);
        for (i, [p, m]) in rows.iter().enumerate() {
            let at = |e: u32| items[e as usize];
            let plus = (at(p[0]) + at(p[1])) + (at(p[2]) + at(p[3]));
            let minus = (at(m[0]) + at(m[1])) + (at(m[2]) + at(m[3]));
            assert_eq!(gather.sums(i, |t| *t, |t| *t), (plus, minus), "row {i}");
        }
        // A range of rows counts from its start.
        let part = padded.gather(5..9, &items[..]).first(4);
        assert_eq!(part.sums(0, |t| *t, |t| *t), gather.sums(5, |t| *t, |t| *t));
        // Another cloth's adjacency replaces them (the assignment's has no
        // padded rows), and the lab's comes back.
        let other = ClothBuilder::assignment(10, 10).build().unwrap();
        padded.update::<Vec3A>(other.topology().adjacency(), 1000);
        assert!(padded.is_empty());
        padded.update::<Vec3A>(model.topology().adjacency(), springs + 1);
        assert_eq!(padded.len(), rows.len());
    }

    #[test]
    #[should_panic(expected = "padded row index")]
    fn padded_rows_refuse_an_index_past_their_items() {
        let model = ClothBuilder::lab().build().unwrap();
        // One item short: the pad's index has nothing to read.
        let springs = model.topology().springs().len();
        PaddedRows::default().update::<Vec3A>(model.topology().adjacency(), springs);
    }

    #[test]
    #[should_panic]
    fn a_gather_refuses_items_shorter_than_its_rows_were_checked_against() {
        let (model, rows) = lab_rows();
        let springs = model.topology().springs().len();
        let mut padded = PaddedRows::default();
        padded.update::<Vec3A>(model.topology().adjacency(), springs + 1);
        let short = vec![Vec3A::ZERO; springs];
        padded.gather(0..rows.len(), &short[..]);
    }

    #[test]
    fn spring_ends_are_the_springs_own_positions() {
        let model = ClothBuilder::lab().build().unwrap();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut seed = 5;
        for x in &mut state.positions {
            *x += 0.1 * noise(&mut seed);
        }
        let x = &state.positions;
        let springs = model.topology().springs();
        let coeffs: Vec<[f32; 2]> = springs.iter().map(|s| [1.0, s.rest_length]).collect();
        let mut seen = 0;
        spring_scales_ends(Springs::of(&model), &coeffs, x, |e, d, scale, xa, xb| {
            let s = &springs[e];
            assert_eq!((xa, xb), (x[s.a as usize], x[s.b as usize]));
            assert_eq!(d, xa - xb);
            let l = d.length();
            assert!((scale - (1.0 - s.rest_length / l)).abs() < 1e-5);
            seen += 1;
        });
        assert_eq!(seen, springs.len());
    }

    #[test]
    #[should_panic]
    fn spring_ends_refuse_too_few_positions() {
        let model = ClothBuilder::lab().build().unwrap();
        let coeffs = vec![[0.0; 2]; model.topology().springs().len()];
        let x = vec![Vec3A::ZERO; model.vertex_count() - 1];
        spring_scales_ends(Springs::of(&model), &coeffs, &x, |_, _, _, _, _| {});
    }
}
