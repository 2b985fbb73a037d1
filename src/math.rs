//! The small linear algebra the engine is written in: vectors and matrices of the simulation's
//! dimension, their determinant, and the cell index of a coordinate.

/// A column vector of the simulation's dimension.
pub type Vector<const D: usize> = nalgebra::SVector<f64, D>;
/// A square matrix of the simulation's dimension.
pub type Matrix<const D: usize> = nalgebra::SMatrix<f64, D, D>;

/// `⌊x⌋` as an integer, without the library call `f64::floor` makes on baseline x86-64 (the
/// same value for every `x`, saturating at the ends of `i64` like `x.floor() as i64`).
#[inline(always)]
pub fn floor_index(x: f64) -> i64 {
    let t = x as i64;
    t.saturating_sub(((t as f64) > x) as i64)
}

/// Determinant of a `D×D` matrix (closed form for 1, 2 and 3; LU beyond).
#[inline]
pub fn determinant<const D: usize>(m: &Matrix<D>) -> f64 {
    match D {
        1 => m[(0, 0)],
        2 => m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)],
        3 => {
            m[(0, 0)] * (m[(1, 1)] * m[(2, 2)] - m[(1, 2)] * m[(2, 1)])
                - m[(0, 1)] * (m[(1, 0)] * m[(2, 2)] - m[(1, 2)] * m[(2, 0)])
                + m[(0, 2)] * (m[(1, 0)] * m[(2, 1)] - m[(1, 1)] * m[(2, 0)])
        }
        _ => nalgebra::DMatrix::from_column_slice(D, D, m.as_slice()).determinant(),
    }
}

#[cfg(test)]
mod tests {
    /// `floor_index` is `x.floor() as i64` everywhere: near integers, at ±0, at the ends of
    /// `i64`, beyond them, at infinities and NaN.
    #[test]
    fn floor_index_is_the_floor() {
        let mut xs = vec![0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.5, -2.5, 1e300, -1e300];
        xs.extend([
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ]);
        xs.extend([
            9.2e18,
            -9.2e18,
            9.3e18,
            -9.3e18,
            -9_223_372_036_854_775_808.0,
        ]);
        for k in -1000..1000 {
            let x = k as f64 * 0.173;
            xs.extend([
                x,
                x.next_up(),
                x.next_down(),
                k as f64,
                (k as f64).next_down(),
            ]);
        }
        for x in xs {
            assert_eq!(super::floor_index(x), x.floor() as i64, "x = {x:e}");
        }
    }
}
