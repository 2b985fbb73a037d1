//! The complete monomial basis of degree ≤ n in `D` variables, shared by the RK basis `H(z)`
//! and the VC test polynomials `Q(z)`.

use crate::Vector;

/// Highest degree a basis may have.
pub const MAX_DEGREE: usize = 8;

/// Monomials `z^e` with `|e| ≤ degree`, the constant first, then by degree.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Monomials<const D: usize> {
    exponents: Vec<[u32; D]>,
}

impl<const D: usize> Monomials<D> {
    /// The monomials of degree ≤ `degree` (at most `MAX_DEGREE` = 8).
    pub fn up_to(degree: u32) -> Self {
        assert!(
            degree as usize <= MAX_DEGREE,
            "monomial degree above {MAX_DEGREE}"
        );
        let mut exponents = Vec::new();
        for d in 0..=degree {
            of_degree::<D>(d, &mut [0; D], 0, &mut exponents);
        }
        Monomials { exponents }
    }

    pub fn len(&self) -> usize {
        self.exponents.len()
    }

    #[cfg_attr(not(feature = "internals"), allow(dead_code))] // clippy's len_without_is_empty
    pub fn is_empty(&self) -> bool {
        self.exponents.is_empty()
    }

    pub fn exponents(&self) -> &[[u32; D]] {
        &self.exponents
    }

    /// Highest degree of the basis.
    fn degree(&self) -> usize {
        self.exponents
            .last()
            .map_or(0, |e| e.iter().sum::<u32>() as usize)
    }

    /// `z_a^p` for every axis and `p ≤ degree` (`MAX_DEGREE` at most).
    #[inline]
    fn powers(&self, z: &Vector<D>) -> [[f64; MAX_DEGREE + 1]; D] {
        let mut pw = [[1.0; MAX_DEGREE + 1]; D];
        for a in 0..D {
            for p in 1..=self.degree().min(MAX_DEGREE) {
                pw[a][p] = pw[a][p - 1] * z[a];
            }
        }
        pw
    }

    /// Writes `z^e` for every monomial into `out`.
    #[inline]
    pub fn values(&self, z: &Vector<D>, out: &mut [f64]) {
        let pw = self.powers(z);
        for (o, e) in out.iter_mut().zip(&self.exponents) {
            let mut v = 1.0;
            for a in 0..D {
                v *= pw[a][e[a] as usize];
            }
            *o = v;
        }
    }

    /// Writes `∂(z^e)/∂z_k` for every monomial into `out`.
    #[inline]
    pub fn derivatives(&self, z: &Vector<D>, k: usize, out: &mut [f64]) {
        let pw = self.powers(z);
        for (o, e) in out.iter_mut().zip(&self.exponents) {
            *o = if e[k] == 0 {
                0.0
            } else {
                let mut v = e[k] as f64;
                for a in 0..D {
                    v *= pw[a][e[a] as usize - usize::from(a == k)];
                }
                v
            };
        }
    }
}

/// Appends the exponents of all monomials of exactly `degree` in `D` variables.
fn of_degree<const D: usize>(degree: u32, e: &mut [u32; D], axis: usize, out: &mut Vec<[u32; D]>) {
    if axis == D - 1 {
        e[axis] = degree;
        out.push(*e);
        return;
    }
    for p in (0..=degree).rev() {
        e[axis] = p;
        of_degree::<D>(degree - p, e, axis + 1, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_and_derivatives() {
        assert_eq!(Monomials::<2>::up_to(2).len(), 6);
        assert_eq!(Monomials::<3>::up_to(3).len(), 20);
        assert_eq!(Monomials::<3>::up_to(0).exponents(), &[[0, 0, 0]]);
        let m = Monomials::<2>::up_to(3);
        let z = Vector::<2>::new(0.3, -1.7);
        let (mut v, mut d) = (vec![0.0; m.len()], vec![0.0; m.len()]);
        let (mut vp, mut vm) = (vec![0.0; m.len()], vec![0.0; m.len()]);
        for k in 0..2 {
            m.derivatives(&z, k, &mut d);
            let mut e = Vector::<2>::zeros();
            e[k] = 1e-6;
            m.values(&(z + e), &mut vp);
            m.values(&(z - e), &mut vm);
            for j in 0..m.len() {
                assert!((d[j] - (vp[j] - vm[j]) / 2e-6).abs() < 1e-8);
            }
        }
        m.values(&z, &mut v);
        assert_eq!(v[0], 1.0);
    }
}
