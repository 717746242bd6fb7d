//! The three-column forward and back substitution on faer's supernodal
//! Cholesky factor that projective dynamics runs every iteration, split
//! over two bins of independent subtrees of the elimination tree.
//!
//! A supernode's rows below its diagonal block are rows of its ancestors in
//! the supernodal elimination tree, so disjoint subtrees never touch each
//! other's rows: in `L⁻¹` each writes its own rows and adds into the rows of
//! the supernodes above them (the "top"), and in `L⁻ᵀ` each reads the
//! finished top rows and writes its own. The plan deals the subtrees to two
//! bins `A` and `B` and renumbers the unknowns as `[A | B | top]` (on top of
//! faer's fill-reducing permutation, in the same gather), so each bin's rows
//! are one contiguous slice:
//!
//! - `L⁻¹`: `A` and `B` (in parallel), their additions into the top rows
//!   kept apart and added after; then the top supernodes;
//! - `L⁻ᵀ`: the top supernodes; then `A` and `B` (in parallel).
//!
//! The operations and their order are the same whether the bins run on one
//! thread or two, so the result is bitwise the same. The split is chosen
//! once per symbolic analysis (it needs faer's supernodes in postorder, and
//! is empty otherwise): starting from the roots' subtrees, the heaviest
//! subtree (by factor entries) is replaced by its children, its root moving
//! to the top, while that lowers the estimated time `top + max(A, B)`, the
//! subtrees dealt heaviest first to the lighter bin. On the perf page's
//! cloths the bins hold 49 % and 43 % of the factor at 201² (4 subtrees),
//! 47 % each at 256² (3 subtrees); splitting at one node into two subtrees
//! only, as first written, left 35 % and 55 % at 201².

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use crate::solver::engine::kernels::dot;

/// One supernode, renumbered: columns `start..start + size`, its rows below
/// the diagonal block (`pattern`), and its values column-major
/// (`size + pattern.len()` rows: the lower-triangular diagonal block, then
/// the rows of `pattern`).
#[derive(Clone, Copy)]
struct Supernode<'a> {
    start: usize,
    size: usize,
    pattern: &'a [usize],
    values: &'a [f64],
}

/// Rows `base..base + own.len()` of `C` columns, which a part writes; any
/// other row it touches is `other_base + i`.
struct Rows<'a, 'b, const C: usize, T> {
    own: &'a mut [&'b mut [f64]; C],
    base: usize,
    other: T,
    other_base: usize,
}

impl Supernode<'_> {
    /// Column `j`: its diagonal block part (from the diagonal down) and its
    /// rows below the block.
    fn column(&self, j: usize) -> (&[f64], &[f64]) {
        let rows = self.size + self.pattern.len();
        self.values[j * rows + j..(j + 1) * rows].split_at(self.size - j)
    }

    /// This supernode's part of `x ← L⁻¹ x`: the triangular diagonal block,
    /// then `L_below · x_block` accumulated in `tmp` (the columns
    /// interleaved) and subtracted from the rows of `pattern` (its own rows,
    /// or added to `other`, the top rows' pending subtractions).
    fn forward<const C: usize>(
        &self,
        x: &mut Rows<'_, '_, C, &mut [&mut [f64]; C]>,
        tmp: &mut Vec<[f64; C]>,
    ) {
        tmp.clear();
        tmp.resize(self.pattern.len(), [0.0; C]);
        let (start, end) = (self.start - x.base, self.start - x.base + self.size);
        for j in 0..self.size {
            let (block, rows) = self.column(j);
            let at = start + j;
            let xj: [f64; C] = core::array::from_fn(|c| {
                let v = x.own[c][at] / block[0];
                x.own[c][at] = v;
                axpy(&mut x.own[c][at + 1..end], -v, &block[1..]);
                v
            });
            for (t, &l) in tmp.iter_mut().zip(rows) {
                for c in 0..C {
                    t[c] += l * xj[c];
                }
            }
        }
        let own_len = x.own[0].len();
        for (&r, t) in self.pattern.iter().zip(tmp.iter()) {
            let i = r.wrapping_sub(x.base);
            if i < own_len {
                for (xc, t) in x.own.iter_mut().zip(t) {
                    xc[i] -= t;
                }
            } else {
                for (dc, t) in x.other.iter_mut().zip(t) {
                    dc[r - x.other_base] += t;
                }
            }
        }
    }

    /// This supernode's part of `x ← L⁻ᵀ x` (supernodes taken in reverse
    /// order): the rows of `pattern` gathered into `tmp` (its own, or the
    /// finished top rows in `other`), then the block's columns from the
    /// last, each a dot product with what is solved.
    fn backward<const C: usize>(
        &self,
        x: &mut Rows<'_, '_, C, &[&[f64]; C]>,
        tmp: &mut Vec<[f64; C]>,
    ) {
        let own_len = x.own[0].len();
        tmp.clear();
        tmp.extend(self.pattern.iter().map(|&r| {
            let i = r.wrapping_sub(x.base);
            if i < own_len {
                core::array::from_fn::<f64, C, _>(|c| x.own[c][i])
            } else {
                core::array::from_fn::<f64, C, _>(|c| x.other[c][r - x.other_base])
            }
        }));
        let (start, end) = (self.start - x.base, self.start - x.base + self.size);
        for j in (0..self.size).rev() {
            let (block, rows) = self.column(j);
            let at = start + j;
            let mut sum = [[0.0f64; C]; 2];
            for (l, t) in rows.chunks_exact(2).zip(tmp.chunks_exact(2)) {
                for h in 0..2 {
                    for c in 0..C {
                        sum[h][c] += l[h] * t[h][c];
                    }
                }
            }
            if rows.len() % 2 == 1 {
                let (l, t) = (rows[rows.len() - 1], tmp[rows.len() - 1]);
                for c in 0..C {
                    sum[0][c] += l * t[c];
                }
            }
            for (c, xc) in x.own.iter_mut().enumerate() {
                let s = sum[0][c] + sum[1][c] + dot(&block[1..], &xc[at + 1..end]);
                xc[at] = (xc[at] - s) / block[0];
            }
        }
    }
}

/// `y += a·x` (the compiler vectorises it).
fn axpy(y: &mut [f64], a: f64, x: &[f64]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// faer's supernodal structure, borrowed.
pub(crate) struct Structure<'a> {
    pub begin: &'a [usize],
    pub end: &'a [usize],
    pub row_ptr: &'a [usize],
    pub row_idx: &'a [usize],
    pub val_ptr: &'a [usize],
}

impl<'a> Structure<'a> {
    /// The structure of faer's supernodal factor `s`.
    pub fn of(s: &'a SymbolicSupernodalCholesky<usize>) -> Self {
        Self {
            begin: s.supernode_begin(),
            end: s.supernode_end(),
            row_ptr: s.col_ptr_for_row_idx(),
            row_idx: s.row_idx(),
            val_ptr: s.col_ptr_for_val(),
        }
    }
}

/// The renumbering and split of one symbolic factorisation (see the module
/// docs).
#[derive(Debug, Default)]
pub(crate) struct Plan {
    /// `x[i] = rhs[gather[i]]` per column, and `rhs[i] = x[scatter[i]]`.
    gather: Vec<usize>,
    scatter: Vec<usize>,
    /// Per supernode: its first column, renumbered.
    start: Vec<usize>,
    /// faer's `row_idx`, renumbered.
    rows: Vec<usize>,
    /// The supernodes of bins `A` and `B` (subtrees, as ranges), and the
    /// rest in order.
    parts: [Vec<core::ops::Range<usize>>; 2],
    top: Vec<usize>,
    /// Columns in `A` and in `B`.
    len: [usize; 2],
}

impl Plan {
    /// The plan for `s` under faer's fill-reducing permutation `perm`
    /// (forward, inverse), if any: subtrees dealt to two bins as the module
    /// docs say (both bins empty if faer's supernodes are not in postorder,
    /// which the split relies on).
    pub(crate) fn new(s: &Structure<'_>, perm: Option<(&[usize], &[usize])>) -> Self {
        let (ns, n) = (s.begin.len(), s.end.last().copied().unwrap_or(0));
        let mut supernode_of = vec![0; n];
        for k in 0..ns {
            supernode_of[s.begin[k]..s.end[k]].fill(k);
        }
        // Parent (the supernode of the first row below the block), subtree
        // work (factor entries) and first supernode of each subtree.
        const ROOT: usize = usize::MAX;
        let mut parent = vec![ROOT; ns];
        let mut work: Vec<usize> = (0..ns).map(|k| s.val_ptr[k + 1] - s.val_ptr[k]).collect();
        let mut first: Vec<usize> = (0..ns).collect();
        let mut count = vec![1usize; ns];
        let mut postorder = true;
        for k in 0..ns {
            if let Some(&r) = s.row_idx[s.row_ptr[k]..s.row_ptr[k + 1]].iter().min() {
                let p = supernode_of[r];
                postorder &= p > k;
                parent[k] = p;
                if p < ns && p > k {
                    work[p] += work[k];
                    first[p] = first[p].min(first[k]);
                    count[p] += count[k];
                }
            }
        }
        postorder &= (0..ns).all(|k| count[k] == k + 1 - first[k]);
        // Split: start from the roots' subtrees; while it lowers the
        // estimated time `top + max(bin A, bin B)` (the subtrees dealt to the
        // two bins heaviest first, each to the lighter bin), replace the
        // heaviest subtree by its children and move its root to the top.
        let mut children = vec![Vec::new(); ns + 1];
        for k in 0..ns {
            children[if parent[k] == ROOT { ns } else { parent[k] }].push(k);
        }
        let deal = |subtrees: &[usize]| {
            let mut sorted = subtrees.to_vec();
            sorted.sort_by_key(|&k| (core::cmp::Reverse(work[k]), k));
            let mut bins: [(usize, Vec<usize>); 2] = Default::default();
            for k in sorted {
                let lighter = usize::from(bins[1].0 < bins[0].0);
                bins[lighter].0 += work[k];
                bins[lighter].1.push(k);
            }
            bins
        };
        let total = s.val_ptr[ns];
        let cost = |subtrees: &[usize]| {
            let bins = deal(subtrees);
            let parts = bins[0].0 + bins[1].0;
            total - parts + bins[0].0.max(bins[1].0)
        };
        let mut subtrees = if postorder {
            children[ns].clone()
        } else {
            Vec::new()
        };
        for _ in 0..64 {
            let Some(&heaviest) = subtrees.iter().max_by_key(|&&k| (work[k], k)) else {
                break;
            };
            let mut next: Vec<usize> = subtrees
                .iter()
                .copied()
                .filter(|&k| k != heaviest)
                .collect();
            next.extend(&children[heaviest]);
            if cost(&next) >= cost(&subtrees) {
                break;
            }
            subtrees = next;
        }
        let bins = deal(&subtrees);
        // Each bin's subtrees in order, as supernode ranges.
        let parts: [Vec<core::ops::Range<usize>>; 2] = core::array::from_fn(|b| {
            let mut roots = bins[b].1.clone();
            roots.sort_unstable();
            roots.into_iter().map(|k| first[k]..k + 1).collect()
        });
        // Renumber: bin A's columns, bin B's, then the rest in order.
        let mut in_part = vec![false; ns];
        let mut old_of_new = Vec::with_capacity(n);
        let mut len = [0; 2];
        for (b, ranges) in parts.iter().enumerate() {
            for r in ranges {
                in_part[r.clone()].fill(true);
                old_of_new.extend(s.begin[r.start]..s.end[r.end - 1]);
            }
            len[b] = old_of_new.len() - len.iter().sum::<usize>();
        }
        let top: Vec<usize> = (0..ns).filter(|&k| !in_part[k]).collect();
        for &k in &top {
            old_of_new.extend(s.begin[k]..s.end[k]);
        }
        let mut new_of_old = vec![0; n];
        for (new, &old) in old_of_new.iter().enumerate() {
            new_of_old[old] = new;
        }
        let (gather, scatter) = match perm {
            Some((fwd, inv)) => (
                old_of_new.iter().map(|&o| fwd[o]).collect(),
                inv.iter().map(|&o| new_of_old[o]).collect(),
            ),
            None => (old_of_new, new_of_old.clone()),
        };
        Self {
            gather,
            scatter,
            start: s.begin.iter().map(|&b| new_of_old[b]).collect(),
            rows: s.row_idx.iter().map(|&r| new_of_old[r]).collect(),
            top,
            len,
            parts,
        }
    }

    /// Both parts have work: worth two tasks.
    pub(crate) fn splits(&self) -> bool {
        self.len.iter().all(|&l| l > 0)
    }
}

/// Scratch of one part.
#[derive(Debug, Default)]
pub(crate) struct PartScratch {
    tmp: Vec<[f64; 3]>,
    /// Pending subtractions from the top rows, column-major.
    delta: Vec<f64>,
}

/// Solves `L Lᵀ X = rhs` for three columns (`rhs` column-major `n×3`) with
/// the supernodal factor `values` of structure `s` and its `plan`, on
/// `pool` if given (see the module docs).
pub(crate) fn solve3(
    s: &Structure<'_>,
    values: &[f64],
    plan: &Plan,
    rhs: &mut [f64],
    x: &mut Vec<f64>,
    scratch: &mut [PartScratch; 3],
    pool: Option<&bevy::tasks::ComputeTaskPool>,
) {
    let n = plan.gather.len();
    x.clear();
    for c in 0..3 {
        let column = &rhs[c * n..(c + 1) * n];
        x.extend(plan.gather.iter().map(|&g| column[g]));
    }
    let supernode = |k: usize| Supernode {
        start: plan.start[k],
        size: s.end[k] - s.begin[k],
        pattern: &plan.rows[s.row_ptr[k]..s.row_ptr[k + 1]],
        values: &values[s.val_ptr[k]..s.val_ptr[k + 1]],
    };
    let top_base = plan.len[0] + plan.len[1];
    let top_len = n - top_base;
    let [scratch_a, scratch_b, scratch_top] = scratch;
    let mut columns = split3(x, n);
    // L⁻¹: the parts, then their pending top subtractions, then the top.
    {
        let [a, b, top] = split_parts(&mut columns, plan.len);
        let parts = [(0, a, &mut *scratch_a), (1, b, &mut *scratch_b)];
        let forward_part = |(p, own, scratch): (usize, [&mut [f64]; 3], &mut PartScratch)| {
            let mut own = own;
            scratch.delta.clear();
            scratch.delta.resize(3 * top_len, 0.0);
            let mut delta = split3(&mut scratch.delta, top_len);
            let mut rows = Rows {
                own: &mut own,
                base: if p == 0 { 0 } else { plan.len[0] },
                other: &mut delta,
                other_base: top_base,
            };
            for k in plan.parts[p].iter().flat_map(Clone::clone) {
                supernode(k).forward(&mut rows, &mut scratch.tmp);
            }
        };
        run_both(pool, parts, forward_part);
        let mut top = top;
        for (c, top) in top.iter_mut().enumerate() {
            let (da, db) = (&scratch_a.delta, &scratch_b.delta);
            let range = c * top_len..(c + 1) * top_len;
            for ((t, a), b) in top.iter_mut().zip(&da[range.clone()]).zip(&db[range]) {
                *t -= a + b;
            }
        }
    }
    {
        let mut no_delta: [&mut [f64]; 3] = [&mut [], &mut [], &mut []];
        let mut all: [&mut [f64]; 3] = columns.each_mut().map(|c| &mut **c);
        let mut rows = Rows {
            own: &mut all,
            base: 0,
            other: &mut no_delta,
            other_base: n,
        };
        for &k in &plan.top {
            supernode(k).forward(&mut rows, &mut scratch_top.tmp);
        }
    }
    // L⁻ᵀ: the top, then the parts.
    {
        let mut all: [&mut [f64]; 3] = columns.each_mut().map(|c| &mut **c);
        let mut rows = Rows {
            own: &mut all,
            base: 0,
            other: &[&[][..], &[], &[]],
            other_base: n,
        };
        for &k in plan.top.iter().rev() {
            supernode(k).backward(&mut rows, &mut scratch_top.tmp);
        }
    }
    {
        let [a, b, top] = split_parts(&mut columns, plan.len);
        let top: [&[f64]; 3] = top.map(|t| &*t);
        let top = &top;
        let parts = [(0, a, &mut *scratch_a), (1, b, &mut *scratch_b)];
        let backward_part = |(p, own, scratch): (usize, [&mut [f64]; 3], &mut PartScratch)| {
            let mut own = own;
            let mut rows = Rows {
                own: &mut own,
                base: if p == 0 { 0 } else { plan.len[0] },
                other: top,
                other_base: top_base,
            };
            for k in plan.parts[p].iter().rev().flat_map(|r| r.clone().rev()) {
                supernode(k).backward(&mut rows, &mut scratch.tmp);
            }
        };
        run_both(pool, parts, backward_part);
    }
    for c in 0..3 {
        let (column, solved) = (&mut rhs[c * n..(c + 1) * n], &x[c * n..(c + 1) * n]);
        for (r, &i) in column.iter_mut().zip(&plan.scatter) {
            *r = solved[i];
        }
    }
}

/// The three columns of a column-major `n×3` buffer.
fn split3(x: &mut [f64], n: usize) -> [&mut [f64]; 3] {
    let (x0, rest) = x.split_at_mut(n);
    let (x1, x2) = rest.split_at_mut(n);
    [x0, x1, x2]
}

/// The three columns split into their rows of `A`, of `B` and of the top
/// (`len` rows in `A` and in `B`): per part, its three columns.
fn split_parts<'a>(columns: &'a mut [&mut [f64]; 3], len: [usize; 2]) -> [[&'a mut [f64]; 3]; 3] {
    let [x0, x1, x2] = columns.each_mut().map(|c| {
        let (a, rest) = c.split_at_mut(len[0]);
        let (b, top) = rest.split_at_mut(len[1]);
        [Some(a), Some(b), Some(top)]
    });
    let mut parts = [x0, x1, x2];
    core::array::from_fn(|p| core::array::from_fn(|c| parts[c][p].take().expect("taken once")))
}

/// Runs `f` on both items: on `pool` as two tasks, or one after the other.
pub(crate) fn run_both<T: Send>(
    pool: Option<&bevy::tasks::ComputeTaskPool>,
    items: [T; 2],
    f: impl Fn(T) + Send + Sync,
) {
    match pool {
        Some(pool) => {
            let f = &f;
            pool.scope(|scope| {
                for item in items {
                    scope.spawn(async move { f(item) });
                }
            });
        }
        None => items.into_iter().for_each(f),
    }
}
