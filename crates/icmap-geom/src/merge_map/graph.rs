//! Steps 1-3 of the module doc: the overlapping pairs (candidates from the spatial index, then
//! the overlap test) as edges of a graph between the instances of both maps, and its connected
//! groups, each in merge order.

use super::outline::{overlap, Outline};
use super::MergeMapParams;
use crate::store::{GlobalMap, Instance};
use parry2d_f64::bounding_volume::BoundingVolume;
use rayon::prelude::*;
use std::collections::{HashMap, VecDeque};

/// A node of the overlap graph: an instance of `self` (by id) or of `other` (by index in
/// ascending id order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(super) enum Node {
    Mine(u64),
    Theirs(usize),
}

/// An overlapping pair found in step 2.
#[derive(Debug, Clone, Copy)]
pub(super) struct Edge {
    mine: u64,
    theirs: usize,
    share: f64,
    mean: f64,
}

/// A connected group of the overlap graph, in merge order (its first node is the start).
pub(super) struct Group {
    pub(super) order: Vec<Node>,
}

/// Simple union-find over dense indices.
struct UnionFind(Vec<usize>);

impl UnionFind {
    fn find(&mut self, mut x: usize) -> usize {
        while self.0[x] != x {
            self.0[x] = self.0[self.0[x]];
            x = self.0[x];
        }
        x
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.0[hi] = lo;
        }
    }
}

/// Steps 1-2: for each instance of `theirs` (by index), the instances of `this` of its class
/// whose boxes meet its box grown by the gate and that overlap it (in parallel).
pub(super) fn overlap_edges(
    this: &GlobalMap,
    theirs: &[&Instance],
    params: &MergeMapParams,
) -> Vec<Vec<Edge>> {
    let gate = params.gate;
    theirs
        .par_iter()
        .enumerate()
        .map(|(j, b)| {
            let ob = Outline::new(b);
            this.query_aabb(&b.aabb().loosened(gate))
                .into_iter()
                .filter_map(|id| {
                    let a = this.get(id)?;
                    if a.class != b.class {
                        return None;
                    }
                    let (share, mean) = overlap(&ob, &Outline::new(a), gate);
                    (share >= params.min_overlap).then_some(Edge {
                        mine: id,
                        theirs: j,
                        share,
                        mean,
                    })
                })
                .collect()
        })
        .collect()
}

/// The overlap graph on dense node numbers: `other`'s instances first, then `self`'s in order of
/// first appearance among the edges.
struct OverlapGraph {
    n_theirs: usize,
    mine_node: HashMap<u64, usize>,
    mine_ids: Vec<u64>,
    /// Per node: its neighbours with the edge's share and mean distance, by overlap (larger
    /// share, smaller mean distance, lower id).
    adjacency: Vec<Vec<(Node, f64, f64)>>,
    /// The connected parts.
    parts: UnionFind,
}

impl OverlapGraph {
    fn new(n_theirs: usize, edges: &[Vec<Edge>]) -> Self {
        let mut mine_node: HashMap<u64, usize> = HashMap::new();
        let mut mine_ids: Vec<u64> = Vec::new();
        for e in edges.iter().flatten() {
            mine_node.entry(e.mine).or_insert_with(|| {
                mine_ids.push(e.mine);
                n_theirs + mine_ids.len() - 1
            });
        }
        let total = n_theirs + mine_ids.len();
        let mut parts = UnionFind((0..total).collect());
        let mut adjacency: Vec<Vec<(Node, f64, f64)>> = vec![Vec::new(); total];
        for e in edges.iter().flatten() {
            let (a, b) = (mine_node[&e.mine], e.theirs);
            parts.union(a, b);
            adjacency[a].push((Node::Theirs(e.theirs), e.share, e.mean));
            adjacency[b].push((Node::Mine(e.mine), e.share, e.mean));
        }
        for list in &mut adjacency {
            list.sort_by(|x, y| {
                y.1.total_cmp(&x.1)
                    .then(x.2.total_cmp(&y.2))
                    .then(x.0.cmp(&y.0))
            });
        }
        Self {
            n_theirs,
            mine_node,
            mine_ids,
            adjacency,
            parts,
        }
    }

    fn node_of(&self, n: Node) -> usize {
        match n {
            Node::Theirs(j) => j,
            Node::Mine(id) => self.mine_node[&id],
        }
    }

    fn node_at(&self, k: usize) -> Node {
        if k < self.n_theirs {
            Node::Theirs(k)
        } else {
            Node::Mine(self.mine_ids[k - self.n_theirs])
        }
    }

    /// The nodes of each connected part with an edge, by the part's root.
    fn parts(&mut self) -> HashMap<usize, Vec<usize>> {
        let mut members: HashMap<usize, Vec<usize>> = HashMap::new();
        for k in 0..self.adjacency.len() {
            if !self.adjacency[k].is_empty() {
                let root = self.parts.find(k);
                members.entry(root).or_default().push(k);
            }
        }
        members
    }

    /// One part in merge order: from its start (most points, then an instance of `self`, then
    /// the lowest id) breadth-first over the edges, neighbours by overlap. `seen` is shared by
    /// all parts (they are disjoint).
    fn merge_order(
        &self,
        nodes: &[usize],
        seen: &mut [bool],
        n_points: &impl Fn(Node) -> usize,
    ) -> Group {
        let start = nodes
            .iter()
            .map(|&k| self.node_at(k))
            .min_by(|&x, &y| {
                n_points(y)
                    .cmp(&n_points(x))
                    .then(matches!(y, Node::Mine(_)).cmp(&matches!(x, Node::Mine(_))))
                    .then(x.cmp(&y))
            })
            .expect("a group has members");
        let mut order = vec![start];
        seen[self.node_of(start)] = true;
        let mut queue = VecDeque::from([start]);
        while let Some(n) = queue.pop_front() {
            for &(next, _, _) in &self.adjacency[self.node_of(n)] {
                let k = self.node_of(next);
                if !seen[k] {
                    seen[k] = true;
                    order.push(next);
                    queue.push_back(next);
                }
            }
        }
        Group { order }
    }
}

/// Step 3: the connected groups of the overlap graph of `edges` (between `n_theirs` instances
/// of `other` and those of `self`), each in merge order, in a fixed order (by the group's lowest
/// node). `n_points`: the number of points of a node's instance.
pub(super) fn groups(
    n_theirs: usize,
    edges: &[Vec<Edge>],
    n_points: impl Fn(Node) -> usize,
) -> Vec<Group> {
    let mut graph = OverlapGraph::new(n_theirs, edges);
    let members = graph.parts();
    let mut seen = vec![false; graph.adjacency.len()];
    let mut groups: Vec<Group> = members
        .into_values()
        .map(|nodes| graph.merge_order(&nodes, &mut seen, &n_points))
        .collect();
    groups.sort_by_key(|g| g.order.iter().copied().min());
    groups
}
