//! VC's coefficients carried by grid node from one solve to the steps that follow it, which
//! take them instead of solving ([`super::VcSolve::interval`]), and to the next solve, which
//! starts from them.

use rayon::prelude::*;

/// The last solve's coefficients by grid node, and the steps committed since.
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
}

impl CarriedCoefficients {
    /// Whether no solve is carried.
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Forgets the carried solve.
    pub fn clear(&mut self) {
        for &n in &self.nodes {
            self.by_node[n * self.per..(n + 1) * self.per].fill(0.0);
        }
        self.nodes.clear();
        self.age = 0;
    }

    /// The coefficients of the nodes `active` (in slot order, `per` values a node): the carried
    /// ones, zero at a node the solve did not take (and everywhere when it had another `per`).
    pub fn at(&self, active: &[usize], per: usize) -> Vec<f64> {
        let mut out = vec![0.0; active.len() * per];
        if per == self.per && !self.is_empty() {
            out.par_chunks_exact_mut(per)
                .zip(active.par_iter())
                .for_each(|(o, &n)| o.copy_from_slice(&self.by_node[n * per..(n + 1) * per]));
        }
        out
    }

    /// Carries `values` (`per` a node) of `nodes` (slot order) on a grid of `node_count`
    /// nodes, as the solve of the step just committed; its age is zero.
    pub fn replace(&mut self, nodes: Vec<usize>, values: &[f64], per: usize, node_count: usize) {
        if self.per != per || self.by_node.len() != node_count * per {
            self.by_node.clear();
            self.by_node.resize(node_count * per, 0.0);
            self.nodes.clear();
            self.per = per;
        }
        self.clear();
        for (&n, v) in nodes.iter().zip(values.chunks_exact(per)) {
            self.by_node[n * per..(n + 1) * per].copy_from_slice(v);
        }
        self.nodes = nodes;
    }

    /// Values a node.
    pub fn per(&self) -> usize {
        self.per
    }

    /// The carried nodes (slot order of the solve) with their values.
    pub fn entries(&self) -> impl Iterator<Item = (usize, &[f64])> + '_ {
        self.nodes
            .iter()
            .map(|&n| (n, &self.by_node[n * self.per..(n + 1) * self.per]))
    }
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
        assert_eq!(c.age, 0);
        assert_eq!(
            c.at(&[1, 3, 5, 0], 2),
            vec![0.0, 0.0, 9.0, 10.0, 0.0, 0.0, 7.0, 8.0]
        );
        let entries: Vec<(usize, Vec<f64>)> = c.entries().map(|(n, v)| (n, v.to_vec())).collect();
        assert_eq!(entries, vec![(0, vec![7.0, 8.0]), (3, vec![9.0, 10.0])]);
        c.clear();
        assert!(c.is_empty());
        assert_eq!(c.at(&[0, 3], 2), vec![0.0; 4]);
    }
}
