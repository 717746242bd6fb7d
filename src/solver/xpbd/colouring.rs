//! The springs in Gauss–Seidel order: grouped by colour, so that no two
//! springs of one colour share a vertex.

use crate::model::ClothModel;

/// The springs as the substep's Gauss–Seidel sweep reads them, in colour
/// order, by field: ends, rest lengths, and how much of its violation each
/// end takes (`wₐ/(wₐ + w_b + α̃)` and `w_b/(…)`, with `w` the inverse
/// masses, zero at a pin, and `α̃ = 1/(k h²)` the compliance over the
/// substep squared).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Links {
    pub(crate) ends: Vec<[u32; 2]>,
    pub(crate) rest: Vec<f32>,
    pub(crate) shares: Vec<[f32; 2]>,
    /// What they were taken from: the topology's id, the stiffnesses and
    /// the substep (their bits), the masses and the pins.
    source: Option<(u64, [u32; 3], u32)>,
    masses: Vec<f32>,
    pinned: Vec<bool>,
}

impl Links {
    /// Takes the links of `model`'s springs in `colouring`'s order for
    /// stiffnesses `k` (per kind) at substep `h`, unless these are already
    /// theirs: a step whose cloth, stiffness and substep are the last
    /// step's keeps them (taking them is a division per spring, a twentieth
    /// of a 201² step's 32 sweeps).
    pub(crate) fn update(
        &mut self,
        model: &ClothModel,
        colouring: &Colouring,
        k: [f32; 3],
        h: f32,
    ) {
        let source = (
            model.topology().adjacency().id(),
            k.map(f32::to_bits),
            h.to_bits(),
        );
        if self.source == Some(source)
            && self.masses.as_slice() == model.masses()
            && self.pinned.as_slice() == model.pinned()
        {
            return;
        }
        self.source = Some(source);
        self.masses.clear();
        self.masses.extend_from_slice(model.masses());
        self.pinned.clear();
        self.pinned.extend_from_slice(model.pinned());
        let springs = model.topology().springs();
        let inv_h2 = f64::from(1.0 / h) * f64::from(1.0 / h);
        let weight = |i: u32| {
            if self.pinned[i as usize] {
                0.0
            } else {
                1.0 / self.masses[i as usize]
            }
        };
        self.ends.clear();
        self.rest.clear();
        self.shares.clear();
        for &e in &colouring.order {
            let s = springs[e as usize];
            let (wa, wb) = (weight(s.a), weight(s.b));
            let compliance = (inv_h2 / f64::from(k[s.kind as usize])) as f32;
            let total = wa + wb + compliance;
            let shares = if total > 0.0 {
                [wa / total, wb / total]
            } else {
                [0.0, 0.0]
            };
            self.ends.push([s.a, s.b]);
            self.rest.push(s.rest_length);
            self.shares.push(shares);
        }
    }
}

/// The model's springs ordered by colour (a greedy edge colouring in spring
/// order): `order[colours[c]..colours[c + 1]]` are the springs of colour `c`,
/// which share no vertex. Taken once per topology (the adjacency's id).
#[derive(Clone, Debug, Default)]
pub(crate) struct Colouring {
    /// Spring indices, colour by colour.
    pub(crate) order: Vec<u32>,
    /// Where each colour starts in `order`, and its end.
    pub(crate) colours: Vec<usize>,
    source: Option<u64>,
}

impl Colouring {
    /// Colours `model`'s springs, unless these are already its.
    pub(crate) fn update(&mut self, model: &ClothModel) {
        let adjacency = model.topology().adjacency();
        if self.source == Some(adjacency.id()) {
            return;
        }
        self.source = Some(adjacency.id());
        let springs = model.topology().springs();
        // Per vertex, the colours its springs already have (a bit each);
        // a spring takes the lowest colour free at both ends. Greedy needs
        // at most 2·(max degree) − 1 colours; past 64 a spring goes to one
        // more colour without the guarantee, which a serial sweep does not
        // need (it only orders the springs).
        let mut used = vec![0u64; model.vertex_count()];
        let mut colour_of = Vec::with_capacity(springs.len());
        let mut counts = vec![0usize; 65];
        for s in springs {
            let taken = used[s.a as usize] | used[s.b as usize];
            let c = (!taken).trailing_zeros() as usize;
            if c < 64 {
                used[s.a as usize] |= 1 << c;
                used[s.b as usize] |= 1 << c;
            }
            colour_of.push(c.min(64) as u8);
            counts[c.min(64)] += 1;
        }
        let last = counts.iter().rposition(|&c| c > 0).map_or(0, |c| c + 1);
        self.colours.clear();
        self.colours.push(0);
        for &count in &counts[..last] {
            let end = self.colours.last().copied().unwrap_or(0) + count;
            self.colours.push(end);
        }
        let mut next = self.colours.clone();
        self.order.clear();
        self.order.resize(springs.len(), 0);
        for (e, &c) in colour_of.iter().enumerate() {
            let at = &mut next[c as usize];
            self.order[*at] = e as u32;
            *at += 1;
        }
    }

    /// The number of colours.
    pub(crate) fn count(&self) -> usize {
        self.colours.len().saturating_sub(1)
    }
}
