//! A cloth's springs as offset families: the structure the grid kernels
//! of the engine room (`solver::engine::stencil`) run on, found once when
//! the cloth's topology is built.
//!
//! Every spring `(a, a + o)` belongs to one of a few offset families `o` (a
//! grid numbered row by row: the lab's triangle grid has three, `1`, `W`
//! and `W + 1`; the assignment's cloth six).

use std::collections::BTreeMap;

use super::Spring;

/// At most this many offset families: more, and the cloth is not a grid
/// the stencil is worth it for (each family costs a pass over all
/// vertices).
pub(crate) const MAX_FAMILIES: usize = 8;

/// No spring of this family starts at the vertex (its kind's slot).
pub(crate) const NONE: u8 = 3;

/// A cloth's springs as offset families (see the [module docs](self)), or
/// nothing when they do not form a stencil.
#[derive(Clone, Debug, Default)]
pub(crate) struct Stencil {
    /// Unique per built stencil (clones share it: same contents), so a
    /// workspace can tell that its coefficients are this stencil's.
    pub(crate) id: u64,
    /// The families' offsets `o`, increasing.
    pub(crate) offsets: Vec<usize>,
    /// Per family, per vertex `a`: the kind of the spring `(a, a + o)`
    /// (its index in [`SpringKind::ALL`](crate::model::SpringKind::ALL)),
    /// or [`NONE`]; `n` entries per family.
    pub(crate) kinds: Vec<u8>,
    /// Per family, per vertex: that spring's rest length (0 for none).
    pub(crate) rest: Vec<f32>,
}

/// Equal contents (the [`id`](Stencil::id) aside).
impl PartialEq for Stencil {
    fn eq(&self, other: &Self) -> bool {
        (&self.offsets, &self.kinds, &self.rest) == (&other.offsets, &other.kinds, &other.rest)
    }
}

impl Stencil {
    /// The families of `springs` over `n` vertices, or `None` when there
    /// are more than [`MAX_FAMILIES`] offsets or the families are less than
    /// half full (most of the dense passes would be wasted).
    pub(crate) fn build(n: usize, springs: &[Spring]) -> Option<Self> {
        if springs.is_empty() {
            return None;
        }
        let mut by_offset: BTreeMap<usize, Vec<&Spring>> = BTreeMap::new();
        for s in springs {
            let o = (s.b - s.a) as usize;
            if !by_offset.contains_key(&o) && by_offset.len() == MAX_FAMILIES {
                return None;
            }
            by_offset.entry(o).or_default().push(s);
        }
        let families = by_offset.len();
        if 2 * springs.len() < families * n {
            return None;
        }
        static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        let mut stencil = Self {
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            offsets: by_offset.keys().copied().collect(),
            kinds: vec![NONE; families * n],
            rest: vec![0.0; families * n],
        };
        for (f, family) in by_offset.values().enumerate() {
            for s in family {
                let at = f * n + s.a as usize;
                stencil.kinds[at] = s.kind as u8;
                stencil.rest[at] = s.rest_length;
            }
        }
        Some(stencil)
    }

    /// How many families.
    pub(crate) fn families(&self) -> usize {
        self.offsets.len()
    }

    /// The largest offset.
    pub(crate) fn max_offset(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }
}
