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
}

impl Links {
    /// Empties every field.
    pub(crate) fn clear(&mut self) {
        self.ends.clear();
        self.rest.clear();
        self.shares.clear();
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
