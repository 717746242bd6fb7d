//! The search for the step's pairs: each vertex's swept box in a grid of
//! cells, a hash table filled by a counting sort (see the [parent
//! module](super)).

use bevy::math::{I64Vec3, Vec3A};

use super::{MAX_CELLS, Pair, SelfContacts};
use crate::model::ClothModel;

/// Each vertex's neighbours along stretch and shear springs (not a pair:
/// the spring keeps them apart), for the adjacency it was made from: a
/// short list read in order, where the search looked up each neighbour's
/// spring to read its kind.
#[derive(Clone, Debug, Default)]
pub(super) struct Linked {
    /// The adjacency's id (0: none yet).
    adjacency: u64,
    /// Vertex `i`'s neighbours are `others[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<u32>,
    others: Vec<u32>,
}

impl Linked {
    /// Made anew where `model`'s adjacency is not the one it was made from.
    pub(super) fn update(&mut self, model: &ClothModel) {
        let topology = model.topology();
        let (adjacency, springs) = (topology.adjacency(), topology.springs());
        if self.adjacency == adjacency.id() && self.offsets.len() == model.vertex_count() + 1 {
            return;
        }
        self.offsets.clear();
        self.others.clear();
        self.offsets.push(0);
        for i in 0..model.vertex_count() {
            self.others.extend(
                adjacency
                    .of(i)
                    .iter()
                    .filter(|inc| {
                        springs[inc.spring as usize].kind != crate::model::SpringKind::Bend
                    })
                    .map(|inc| inc.other),
            );
            self.offsets.push(self.others.len() as u32);
        }
        self.adjacency = adjacency.id();
    }

    /// Whether a stretch or shear spring joins `a` and `b`.
    pub(super) fn joins(&self, a: usize, b: usize) -> bool {
        self.others[self.offsets[a] as usize..self.offsets[a + 1] as usize].contains(&(b as u32))
    }
}

pub(super) fn cell_of(p: Vec3A, inv: f32) -> [i64; 3] {
    let q = p * inv;
    [floor(q.x), floor(q.y), floor(q.z)]
}

/// `q.floor() as i64`, without the library call the baseline x86-64 build
/// makes of `floor` (it has no rounding instruction): truncate, and step
/// down where that rounded up (a negative fraction). Saturates alike.
fn floor(q: f32) -> i64 {
    let t = q as i64;
    t.saturating_sub(i64::from((t as f32) > q))
}

/// How many cells the box of cells `lo..=hi` covers (saturating: a box
/// out at infinity covers `i64::MAX`).
pub(super) fn span(lo: [i64; 3], hi: [i64; 3]) -> i64 {
    (0..3)
        .map(|k| hi[k].saturating_sub(lo[k]).saturating_add(1).max(0))
        .fold(1i64, i64::saturating_mul)
}

/// The box of the cells (of `1/inv` m) that the box `lo..hi` (m) overlaps,
/// and how many there are, if they are at most [`MAX_CELLS`] (`None`: more,
/// or not finite). In `f32` and `i32` lanes: this runs for every vertex in
/// every search.
pub(super) fn cell_box(lo: Vec3A, hi: Vec3A, inv: f32) -> Option<(CellBox, usize)> {
    // Well inside `i32` (a NaN fails the comparisons).
    const LIMIT: f32 = 1e9;
    let (lo, hi) = ((lo * inv).floor(), (hi * inv).floor());
    if !(lo.cmpge(Vec3A::splat(-LIMIT)).all() && hi.cmple(Vec3A::splat(LIMIT)).all()) {
        return None;
    }
    let (lo, hi) = (lo.as_ivec3(), hi.as_ivec3());
    let size = (hi - lo + 1).as_i64vec3();
    let cells = size
        .max(I64Vec3::ZERO)
        .to_array()
        .into_iter()
        .fold(1i64, i64::saturating_mul);
    (1..=MAX_CELLS)
        .contains(&cells)
        .then_some(([lo.to_array(), hi.to_array()], cells as usize))
}

/// A box of grid cells, `lo` to `hi` inclusive (empty where `lo > hi`).
pub(super) type CellBox = [[i32; 3]; 2];

/// A box of no cells.
pub(super) const EMPTY_BOX: CellBox = [[0; 3], [-1; 3]];

/// One vertex in one cell of the grid.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Entry {
    /// The vertex, with [`FIRST_FLAG`] `<< k` set where the cell is the
    /// vertex's box's lowest along axis `k`.
    vertex: u32,
    cell: [i32; 3],
}

/// The lowest bit of an [`Entry`]'s three flags: a cloth's vertices beyond
/// it (half a billion) are left out of the pairs.
const FIRST_FLAG: u32 = 1 << 29;

/// All three flags of an [`Entry`]: the entry's vertex number is below.
const ALL_FLAGS: u32 = 7 << 29;

/// Calls `f` with every cell of the box of cells `b` (inclusive).
pub(super) fn for_each_cell(b: &CellBox, mut f: impl FnMut([i32; 3])) {
    for cx in b[0][0]..=b[1][0] {
        for cy in b[0][1]..=b[1][1] {
            for cz in b[0][2]..=b[1][2] {
                f([cx, cy, cz]);
            }
        }
    }
}

/// The hash-table bucket of cell `c` (`mask`: the table's size less one).
pub(super) fn bucket(c: [i32; 3], mask: u64) -> usize {
    let h = (c[0] as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (c[1] as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (c[2] as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    ((h ^ (h >> 29)) & mask) as usize
}

/// Counting-sorts the cells of `boxes` (`total` of them) into a hash table
/// of about twice their number, each cell's entry made by `entry(index,
/// box, cell)`: bucket `b`'s entries are `entries[starts[b]..starts[b +
/// 1]]`, in increasing index order. Returns the table's mask (for
/// [`bucket`]).
pub(super) fn fill_table<E: Copy + Default>(
    boxes: &[CellBox],
    total: usize,
    starts: &mut Vec<u32>,
    entries: &mut Vec<E>,
    mut entry: impl FnMut(usize, &CellBox, [i32; 3]) -> E,
) -> u64 {
    let buckets = (2 * total).next_power_of_two().max(2);
    let mask = buckets as u64 - 1;
    starts.clear();
    starts.resize(buckets + 1, 0);
    for b in boxes {
        for_each_cell(b, |c| starts[bucket(c, mask)] += 1);
    }
    let mut sum = 0;
    for s in starts.iter_mut() {
        sum += *s;
        *s = sum;
    }
    // `starts[b]` is now the end of bucket `b`: filled backwards from the
    // last box, each bucket ends up in increasing order and `starts[b]` at
    // its start.
    entries.clear();
    entries.resize(total, E::default());
    for (i, b) in boxes.iter().enumerate().rev() {
        for_each_cell(b, |cell| {
            let s = &mut starts[bucket(cell, mask)];
            *s -= 1;
            entries[*s as usize] = entry(i, b, cell);
        });
    }
    mask
}

/// The mean of the finite velocities of `v` (zero if there are none, or
/// if it is not finite): the frame the swept boxes are swept in.
pub(super) fn mean_velocity(v: &[Vec3A]) -> Vec3A {
    let (sum, count) = v
        .iter()
        .filter(|v| v.is_finite())
        .fold((Vec3A::ZERO, 0u32), |(s, c), &v| (s + v, c + 1));
    Some(sum / count.max(1) as f32)
        .filter(|u| u.is_finite())
        .unwrap_or(Vec3A::ZERO)
}

/// The least distance between two points moving in straight lines over
/// `t ∈ [0, 1]`: `d` apart at the start, their difference moving by `dd`.
fn closest_approach(d: Vec3A, dd: Vec3A) -> f32 {
    let l2 = dd.length_squared();
    let t = if l2 > 0.0 {
        (-d.dot(dd) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (d + t * dd).length()
}

impl SelfContacts {
    /// [`find`](Self::find) over any vertices: each vertex's box grown by
    /// `half(i)` plus `slack` plus a quarter of its motion, about `cell` (m)
    /// wide at rest, and `pair(a, b)` the least distance and friction of a
    /// pair (`None`: not a pair). The grid's cells are 2.5 times `cell`:
    /// each box then covers about three cells, not eight, and the fuller
    /// cells' extra candidates are turned away by their boxes (before the
    /// closest approach) and by each entry's mark of its box's lowest
    /// cells (before reading the other vertex); the same pairs, bit for
    /// bit, at less than half the cost of cells of `cell` while a cloth
    /// moves (twice and three times `cell` cost more; the numbers are in the
    /// CHANGELOG). The boxes are swept relative to the vertices' mean
    /// velocity (see the loop), so a cloth's common motion does not grow
    /// them.
    pub(super) fn find_where(
        &mut self,
        x: &[Vec3A],
        v: &[Vec3A],
        dt: f32,
        [cell, slack]: [f32; 2],
        half: impl Fn(usize) -> f32,
        pair: impl Fn(usize, usize) -> Option<(f32, f32)>,
    ) {
        self.pairs.clear();
        self.boxes.clear();
        self.skipped = 0;
        let n = x.len().min(v.len());
        if n < 2 || cell.is_nan() || cell <= 0.0 {
            return;
        }
        let inv = 0.4 / cell;
        // Each vertex's margin and swept box, in metres and in cells.
        let mut total = 0usize;
        self.margins.clear();
        self.extents.clear();
        // The boxes are swept in the frame that moves with the vertices'
        // mean velocity: two paths meet in it where they meet in the world,
        // and a cloth falling or carried as a whole has boxes the size of
        // its vertices' motion relative to each other, not of its speed.
        let frame = mean_velocity(&v[..n]);
        for i in 0..n {
            let end = x[i] + v[i] * dt;
            let m = half(i) + slack + 0.25 * v[i].length() * dt;
            let to = x[i] + (v[i] - frame) * dt;
            let (lo, hi) = (x[i].min(to) - m, x[i].max(to) + m);
            self.margins.push(m);
            self.extents.push([lo, hi]);
            let cells =
                (i < FIRST_FLAG as usize && x[i].is_finite() && end.is_finite() && m.is_finite())
                    .then(|| cell_box(lo, hi, inv))
                    .flatten();
            match cells {
                Some((b, cells)) => {
                    total += cells;
                    self.boxes.push(b);
                }
                None => {
                    self.skipped += 1;
                    self.boxes.push(EMPTY_BOX);
                }
            }
        }
        // A counting sort of the (cell, vertex) entries into the buckets of
        // a hash table of about twice their number: linear, where a sort of
        // the entries was most of the step's self-collision cost.
        let mask = fill_table(
            &self.boxes,
            total,
            &mut self.starts,
            &mut self.entries,
            |i, b, cell| {
                // Which of the box's lowest cells (per axis) this one is.
                let lowest = (0..3)
                    .filter(|&k| cell[k] == b[0][k])
                    .fold(0, |f, k| f | FIRST_FLAG << k);
                Entry {
                    vertex: i as u32 | lowest,
                    cell,
                }
            },
        );
        let (margins, extents) = (&self.margins, &self.extents);
        // Bucket by bucket, the empty ones passed over: from each bucket's
        // first entry, its cell's bucket says where it ends.
        let mut start = 0;
        while start < total {
            let end = self.starts[bucket(self.entries[start].cell, mask) + 1] as usize;
            let here = &self.entries[start..end];
            start = end;
            for (k, ea) in here.iter().enumerate() {
                let a = (ea.vertex & (FIRST_FLAG - 1)) as usize;
                let [lo_a, hi_a] = extents[a];
                for eb in &here[k + 1..] {
                    // Another cell of the same bucket.
                    if eb.cell != ea.cell {
                        continue;
                    }
                    // The pair is tested in the lowest cell the two boxes
                    // share only: once. (Each box holds the cell, so the
                    // larger of their lowest cells along an axis is the
                    // cell's exactly where one of them starts there.)
                    if (ea.vertex | eb.vertex) < ALL_FLAGS {
                        continue;
                    }
                    let b2 = (eb.vertex & (FIRST_FLAG - 1)) as usize;
                    // The swept boxes meet (a pair within the margins'
                    // reach has boxes that do), then the closest approach
                    // within the largest least distance a pair can have
                    // (the two half thicknesses), before the pair's own
                    // test.
                    let [lo_b, hi_b] = extents[b2];
                    if lo_a.cmpgt(hi_b).any() || lo_b.cmpgt(hi_a).any() {
                        continue;
                    }
                    let d = x[b2] - x[a];
                    let approach = closest_approach(d, (v[b2] - v[a]) * dt);
                    let (ma, mb) = (margins[a], margins[b2]);
                    if approach > ma + mb {
                        continue;
                    }
                    let Some((min, friction)) = pair(a, b2) else {
                        continue;
                    };
                    let reach = min + ma - half(a) + mb - half(b2);
                    if approach <= reach {
                        let d0 = d.length();
                        self.pairs.push(Pair {
                            a: a as u32,
                            b: b2 as u32,
                            min,
                            friction,
                            overlap: if d0 < min { d0 } else { f32::INFINITY },
                        });
                    }
                }
            }
        }
        // In the pair order the resolution sweeps: the same on any thread
        // count.
        self.pairs
            .sort_unstable_by_key(|p| (u64::from(p.a) << 32) | u64::from(p.b));
    }
}

#[cfg(test)]
mod tests {
    use super::floor;

    #[test]
    fn floor_is_the_library_floor_saturated_alike() {
        let values = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            -1.000_001,
            2.999_999,
            -7.25,
            16_777_217.0,
            -16_777_217.0,
            3e9,
            -3e9,
            1e30,
            -1e30,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
        ];
        for q in values {
            assert_eq!(floor(q), q.floor() as i64, "{q}");
        }
    }
}
