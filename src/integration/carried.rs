//! VC's coefficients carried by grid node from one solve to the steps that follow it, which
//! take them instead of solving ([`super::VcSolve::interval`]; on wide grids after sweeps on
//! their own system, `super::carried_sweeps_for`), and to the next solve, which
//! starts from them. With the solve before it kept too, the carried values go on along the line
//! through both (extrapolated linearly in time): the particles move, and the coefficients that
//! the solve would give move with them, which a value held constant lags.

use rayon::prelude::*;

/// The last solve's coefficients by grid node, the steps committed since, and the solve before
/// it.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct CarriedCoefficients {
    /// `per` values a node, by grid storage index; zero at every node not in `nodes`.
    by_node: Vec<f64>,
    /// The nodes the solve took, in its slot order.
    nodes: Vec<usize>,
    /// Values a node: the test polynomials times the dimension.
    per: usize,
    /// Steps committed since the solve's own.
    pub age: u32,
    /// The solve before the last, as `by_node` and `nodes`.
    before: Vec<f64>,
    before_nodes: Vec<usize>,
    /// By grid storage index, which of the two solves took the node (`LAST`, `BEFORE`).
    taken: Vec<u8>,
    /// Steps from the solve before to the last; zero when there is none.
    span: u32,
    /// The largest squared norm of the last solve's node values.
    largest: f64,
}

/// The change between the two solves at a node, against the largest coefficient, up to which
/// the carried values go on along their line whatever the node's own size.
const SMOOTH_CHANGE: f64 = 0.1;

const LAST: u8 = 1;
const BEFORE: u8 = 2;

impl CarriedCoefficients {
    /// Whether no solve is carried.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Forgets the carried solves.
    pub fn clear(&mut self) {
        self.forget_before();
        for &n in &self.nodes {
            self.by_node[n * self.per..(n + 1) * self.per].fill(0.0);
            self.taken[n] &= !LAST;
        }
        self.nodes.clear();
        self.age = 0;
    }

    fn forget_before(&mut self) {
        for &n in &self.before_nodes {
            self.before[n * self.per..(n + 1) * self.per].fill(0.0);
            self.taken[n] &= !BEFORE;
        }
        self.before_nodes.clear();
        self.span = 0;
    }

    /// The coefficients of the nodes `active` (in slot order, `per` values a node) one step
    /// after the last committed: the carried ones, `c + t (c − b)` at a node that both solves
    /// took (`b`, `span` steps earlier; `t = (age + 1) / span`), zero at a node the
    /// last solve did not take (and everywhere when it had another `per`).
    pub fn at(&self, active: &[usize], per: usize) -> Vec<f64> {
        let mut out = vec![0.0; active.len() * per];
        if per != self.per || self.is_empty() {
            return out;
        }
        let t = match self.span {
            0 => 0.0,
            span => f64::from(self.age + 1) / f64::from(span),
        };
        let smooth = SMOOTH_CHANGE * SMOOTH_CHANGE * self.largest;
        out.par_chunks_exact_mut(per)
            .zip(active.par_iter())
            .for_each(|(o, &n)| {
                let c = &self.by_node[n * per..(n + 1) * per];
                o.copy_from_slice(c);
                if self.span > 0 && self.taken[n] == LAST | BEFORE {
                    let b = &self.before[n * per..(n + 1) * per];
                    // Where the solves moved smoothly: the change between them not larger than
                    // the coefficient, or than a tenth of the largest (at a breaking surface
                    // they jump, and a line through them would throw the next far off).
                    let change: f64 = c.iter().zip(b).map(|(c, b)| (c - b) * (c - b)).sum();
                    let size: f64 = c.iter().map(|c| c * c).sum();
                    if change <= size.max(smooth) {
                        for ((o, c), b) in o.iter_mut().zip(c).zip(b) {
                            *o = c + t * (c - b);
                        }
                    }
                }
            });
        out
    }

    /// Carries `values` (`per` a node) of `nodes` (slot order) on a grid of `node_count`
    /// nodes, as the solve of the step just committed; its age is zero, and the solve it
    /// replaces becomes the one before (`age + 1` steps earlier).
    pub fn replace(&mut self, nodes: Vec<usize>, values: &[f64], per: usize, node_count: usize) {
        if self.per != per || self.by_node.len() != node_count * per {
            *self = CarriedCoefficients {
                by_node: vec![0.0; node_count * per],
                before: vec![0.0; node_count * per],
                taken: vec![0; node_count],
                per,
                ..CarriedCoefficients::default()
            };
        }
        self.forget_before();
        if !self.is_empty() {
            // The cleared `before` becomes the storage of the new solve.
            std::mem::swap(&mut self.by_node, &mut self.before);
            std::mem::swap(&mut self.nodes, &mut self.before_nodes);
            for &n in &self.before_nodes {
                self.taken[n] = BEFORE;
            }
            self.span = self.age + 1;
        }
        for (&n, v) in nodes.iter().zip(values.chunks_exact(per)) {
            self.by_node[n * per..(n + 1) * per].copy_from_slice(v);
            self.taken[n] |= LAST;
        }
        self.largest = values
            .chunks_exact(per)
            .map(|v| v.iter().map(|v| v * v).sum::<f64>())
            .fold(0.0, f64::max);
        self.nodes = nodes;
        self.age = 0;
    }

    /// Restores the solve before the last (`nodes`, slot order, with `values`), `span` steps
    /// before it, as a checkpoint holds it; after [`CarriedCoefficients::replace`] of the last.
    pub fn restore_before(&mut self, nodes: Vec<usize>, values: &[f64], span: u32) {
        self.forget_before();
        if self.is_empty() || nodes.is_empty() || span == 0 {
            return;
        }
        let per = self.per;
        for (&n, v) in nodes.iter().zip(values.chunks_exact(per)) {
            self.before[n * per..(n + 1) * per].copy_from_slice(v);
            self.taken[n] |= BEFORE;
        }
        self.before_nodes = nodes;
        self.span = span;
    }

    /// Values a node.
    pub fn per(&self) -> usize {
        self.per
    }

    /// The carried nodes (slot order of the solve) with their values.
    pub fn entries(&self) -> impl Iterator<Item = (usize, &[f64])> + '_ {
        listed(&self.nodes, &self.by_node, self.per)
    }

    /// Steps from the solve before to the last (zero when there is none).
    pub fn span(&self) -> u32 {
        self.span
    }

    /// The solve before the last: its nodes (slot order) with their values.
    pub fn entries_before(&self) -> impl Iterator<Item = (usize, &[f64])> + '_ {
        listed(&self.before_nodes, &self.before, self.per)
    }
}

/// The nodes (in their order) with their `per` values each from `by_node`.
fn listed<'a>(
    nodes: &'a [usize],
    by_node: &'a [f64],
    per: usize,
) -> impl Iterator<Item = (usize, &'a [f64])> + 'a {
    nodes
        .iter()
        .map(move |&n| (n, &by_node[n * per..(n + 1) * per]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The values come back by node whatever the slot order, zero at nodes not carried; a
    /// replacement leaves nothing of the last solve behind.
    #[test]
    fn carried_by_node_across_slot_orders() {
        let mut c = CarriedCoefficients::default();
        assert!(c.is_empty());
        assert_eq!(c.at(&[3, 1], 2), vec![0.0; 4]);
        c.replace(vec![1, 3, 5], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 2, 8);
        assert_eq!(c.at(&[5, 0, 1], 2), vec![5.0, 6.0, 0.0, 0.0, 1.0, 2.0]);
        // Another `per` reads as nothing carried.
        assert_eq!(c.at(&[1], 1), vec![0.0]);
        c.age = 2;
        c.replace(vec![0, 3], &[7.0, 8.0, 9.0, 10.0], 2, 8);
        assert_eq!((c.age, c.span()), (0, 3));
        // Node 3, which both solves took, one step on along the line through them (a third
        // of the three steps between): 9 + (9 − 3)/3, 10 + (10 − 4)/3; nodes 1 and 5, which
        // the last did not take, zero; node 0 its value.
        assert_eq!(
            c.at(&[1, 3, 5, 0], 2),
            vec![0.0, 0.0, 11.0, 12.0, 0.0, 0.0, 7.0, 8.0]
        );
        c.age = 1;
        assert_eq!(c.at(&[3], 2), vec![13.0, 14.0]);
        let before: Vec<(usize, Vec<f64>)> =
            c.entries_before().map(|(n, v)| (n, v.to_vec())).collect();
        assert_eq!(
            before,
            vec![
                (1, vec![1.0, 2.0]),
                (3, vec![3.0, 4.0]),
                (5, vec![5.0, 6.0])
            ]
        );
        // Restored as a checkpoint holds them, the two solves give the same values.
        let mut restored = CarriedCoefficients::default();
        restored.replace(vec![0, 3], &[7.0, 8.0, 9.0, 10.0], 2, 8);
        restored.restore_before(vec![1, 3, 5], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 3);
        restored.age = 1;
        assert_eq!(restored, c);
        let entries: Vec<(usize, Vec<f64>)> = c.entries().map(|(n, v)| (n, v.to_vec())).collect();
        assert_eq!(entries, vec![(0, vec![7.0, 8.0]), (3, vec![9.0, 10.0])]);
        c.clear();
        assert!(c.is_empty());
        assert_eq!(c.at(&[0, 3], 2), vec![0.0; 4]);
    }
}
