//! Vertex order for locality: reverse Cuthill–McKee on the mesh's edge graph.
//!
//! The spring pass reads both ends of every spring and the vertex pass
//! gathers each vertex's springs: when a spring's two vertices are far apart
//! in memory, every read is a cache miss. The builders' grids are numbered
//! row by row (a spring joins vertices at most a row apart), but a mesh read
//! from a file can come in any order: a 101² grid mesh with its vertices
//! shuffled stepped 2.7–3× slower than the same mesh in row order (Chebyshev
//! 32, measured on the perf page's machine; shuffling only the triangles,
//! hence the springs, cost nothing). Reverse Cuthill–McKee (George and Liu,
//! "Computer Solution of Large Sparse Positive Definite Systems", 1981)
//! numbers the vertices breadth first from a peripheral vertex, which puts
//! every edge's ends close together.
//!
//! Written here (about 60 lines) rather than taken from a crate: faer has
//! fill-reducing orderings (AMD, COLAMD) but not this bandwidth-reducing
//! one, and `sprs`'s would bring a second sparse-matrix crate for one
//! function.

use std::collections::VecDeque;

/// A renumbering of `n` vertices joined by the edges of `triangles` that
/// brings every edge's ends close in memory, as `new_of_old` (vertex `v`
/// becomes `new_of_old[v]`), or `None` when the given order is already
/// about as local: the renumbering is kept only if it at least halves the
/// mean distance `|a − b|` between an edge's two vertices.
pub(crate) fn locality_order(n: usize, triangles: &[[u32; 3]]) -> Option<Vec<u32>> {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .filter(|(a, b)| a != b)
        .collect();
    edges.sort_unstable();
    edges.dedup();
    if edges.is_empty() {
        return None;
    }
    // Neighbour lists (CSR), each sorted by degree, then index.
    let mut degree = vec![0u32; n];
    for &(a, b) in &edges {
        degree[a as usize] += 1;
        degree[b as usize] += 1;
    }
    let mut offsets = vec![0usize; n + 1];
    for v in 0..n {
        offsets[v + 1] = offsets[v] + degree[v] as usize;
    }
    let mut fill = offsets.clone();
    let mut neighbours = vec![0u32; offsets[n]];
    for &(a, b) in &edges {
        for (v, w) in [(a, b), (b, a)] {
            neighbours[fill[v as usize]] = w;
            fill[v as usize] += 1;
        }
    }
    for v in 0..n {
        neighbours[offsets[v]..offsets[v + 1]].sort_unstable_by_key(|&w| (degree[w as usize], w));
    }
    let adjacent = |v: u32| &neighbours[offsets[v as usize]..offsets[v as usize + 1]];

    // Breadth first from `root` over unvisited vertices; returns the last
    // level's vertices (for the peripheral search) and appends to `order`.
    let mut visited = vec![false; n];
    let breadth_first = |root: u32, visited: &mut [bool], order: &mut Vec<u32>| {
        let first = order.len();
        let mut queue = VecDeque::from([root]);
        visited[root as usize] = true;
        let mut level_start = first;
        let mut level_end = first;
        while let Some(v) = queue.pop_front() {
            let at = order.len();
            if at == level_end {
                level_start = at;
                level_end = at + queue.len() + 1;
            }
            order.push(v);
            for &w in adjacent(v) {
                if !visited[w as usize] {
                    visited[w as usize] = true;
                    queue.push_back(w);
                }
            }
        }
        level_start..order.len()
    };
    let mut order: Vec<u32> = Vec::with_capacity(n);
    for start in 0..n as u32 {
        if visited[start as usize] {
            continue;
        }
        // A pseudo-peripheral root: twice, restart from the last level's
        // vertex of least degree (George–Liu).
        let mut root = start;
        for _ in 0..2 {
            let mut seen = visited.clone();
            let mut trial = Vec::new();
            let last = breadth_first(root, &mut seen, &mut trial);
            root = trial[last]
                .iter()
                .copied()
                .min_by_key(|&w| (degree[w as usize], w))
                .unwrap_or(root);
        }
        breadth_first(root, &mut visited, &mut order);
    }
    order.reverse();
    let mut new_of_old = vec![0u32; n];
    for (new, &old) in order.iter().enumerate() {
        new_of_old[old as usize] = new as u32;
    }
    let span = |map: &dyn Fn(u32) -> u32| -> u64 {
        edges
            .iter()
            .map(|&(a, b)| u64::from(map(a).abs_diff(map(b))))
            .sum()
    };
    (2 * span(&|v| new_of_old[v as usize]) <= span(&|v| v)).then_some(new_of_old)
}
