//! The order-1 node operator's rows laid out on the box of the lattice they cover, for its
//! products.
//!
//! The packed rows of [`super::node_operator::NodeOperator`] read a column index and then a
//! node's values scattered over the active nodes for every entry. On the box of the lattice
//! that the rows cover, entry `e` of every row is the same flat offset, so the product is a
//! stencil with variable coefficients: `y_i = Σ_e V_e,i ζ_{i + o_e}`, run over `LANES`
//! consecutive box positions at once with the sums held in registers and the coefficients read
//! as one stream. Each row still sums its entries in the packed order (ascending `e`); the
//! entries a packed row leaves out are zero here and add `+0`, which leaves a sum as it is, so
//! the products are the same bits as the packed rows' (`lattice_products_are_the_packed_ones`).

use super::node_operator::entry_steps;
use crate::cpu::Lanes;
use rayon::prelude::*;
use std::sync::Mutex;

/// Box positions computed together: their sums stay in registers (`LANES × D` values, 16
/// with AVX2 in 2D).
const LANES: usize = 8;

/// Chunks of `LANES` positions per task (and per call into the vector code).
const GROUP: usize = 32;

/// The rows stay packed only when they fill less than this fraction of their box (a heap of
/// soil in the corner of its box), where the box's empty positions would cost more than the
/// column indices save.
const MIN_FILL: f64 = 0.5;

/// The rows of a scalar (`m = 1`) operator on their lattice box.
pub(super) struct LatticeRows {
    /// Per row (slot): its box position.
    position: Vec<u32>,
    /// Per box position (rounded up to whole chunks of `LANES`): its row, or `u32::MAX`.
    row_at: Vec<u32>,
    /// Per chunk of `LANES` positions: whether it holds a row.
    occupied: Vec<bool>,
    /// Per entry `e` (ascending): its flat offset in the box.
    offset: Vec<isize>,
    /// Zeros before and after the box in the gathered `ζ`: the largest `|offset|`.
    pad: usize,
    /// Chunk by chunk, entry by entry, `LANES` values: `value[(chunk · entries + e) · LANES + i]`.
    value: Vec<f64>,
    lanes: Lanes,
    /// `ζ` on the box (direction by direction, padded) and the product chunk by chunk.
    scratch: Mutex<(Vec<f64>, Vec<f64>)>,
}

impl LatticeRows {
    /// Lays out the packed rows (`count`, `column`, `value`; `block` entries of room per row,
    /// entries of a row at most `radius` lattice steps from it along every axis) of the rows at
    /// lattice multi-indices `index`. `None` when the rows fill less than `MIN_FILL` of their
    /// box, or a row's entries are not in ascending offset (then the sums' order would change).
    pub fn new<const D: usize>(
        index: &[[i64; D]],
        radius: usize,
        block: usize,
        (count, column, value): (&[u32], &[u32], &[f64]),
        lanes: Lanes,
        mut laid: Vec<f64>,
    ) -> Option<Self> {
        let rows = index.len();
        let span = 2 * radius + 1;
        if rows == 0 || span.pow(D as u32) != block {
            return None;
        }
        let mut lo = index[0];
        let mut hi = index[0];
        for i in index {
            for a in 0..D {
                lo[a] = lo[a].min(i[a]);
                hi[a] = hi[a].max(i[a]);
            }
        }
        let mut stride = [0usize; D];
        let mut positions = 1usize;
        for a in 0..D {
            stride[a] = positions;
            positions = positions.checked_mul((hi[a] - lo[a] + 1) as usize)?;
        }
        if (rows as f64) < MIN_FILL * positions as f64 || positions >= u32::MAX as usize {
            return None;
        }
        let offset: Vec<isize> = entry_steps::<D>(radius)
            .iter()
            .map(|d| (0..D).map(|a| d[a] as isize * stride[a] as isize).sum())
            .collect();
        let pad = offset.iter().map(|o| o.unsigned_abs()).max().unwrap_or(0);
        // Entry `e` of a column `delta` positions away, where one is.
        let mut entry_at = vec![u32::MAX; 2 * pad + 1];
        for (e, &o) in offset.iter().enumerate() {
            entry_at[(o + pad as isize) as usize] = e as u32;
        }
        let position: Vec<u32> = index
            .iter()
            .map(|i| {
                (0..D)
                    .map(|a| (i[a] - lo[a]) as usize * stride[a])
                    .sum::<usize>() as u32
            })
            .collect();
        let chunks = positions.div_ceil(LANES);
        let mut row_at = vec![u32::MAX; chunks * LANES];
        for (row, &p) in position.iter().enumerate() {
            row_at[p as usize] = row as u32;
        }
        let occupied: Vec<bool> = row_at
            .chunks_exact(LANES)
            .map(|c| c.iter().any(|&r| r != u32::MAX))
            .collect();
        laid.clear();
        laid.resize(chunks * block * LANES, 0.0);
        let ordered = laid
            .par_chunks_mut(block * LANES)
            .zip(row_at.par_chunks(LANES))
            .all(|(laid, rows)| {
                rows.iter().enumerate().all(|(i, &row)| {
                    if row == u32::MAX {
                        return true;
                    }
                    let (row, mut last) = (row as usize, None);
                    let start = row * block;
                    (start..start + count[row] as usize).all(|k| {
                        let delta = position[column[k] as usize] as isize - position[row] as isize;
                        let e = match entry_at.get((delta + pad as isize) as usize) {
                            Some(&e) if e != u32::MAX && last.is_none_or(|l| e > l) => e,
                            _ => return false,
                        };
                        last = Some(e);
                        laid[e as usize * LANES + i] = value[k];
                        true
                    })
                })
            });
        ordered.then(|| LatticeRows {
            position,
            row_at,
            occupied,
            offset,
            pad,
            value: laid,
            lanes,
            scratch: Mutex::new((Vec::new(), Vec::new())),
        })
    }

    /// The buffer of the values, for the next operator's layout.
    pub fn into_values(self) -> Vec<f64> {
        self.value
    }

    /// `out = K ζ` for `D` directions stored per row (`ζ[row · D + k]`).
    pub fn apply<const D: usize>(&self, zeta: &[f64], out: &mut [f64]) {
        let mut scratch = self.scratch.lock().unwrap_or_else(|e| e.into_inner());
        let (gathered, product) = &mut *scratch;
        let n = self.row_at.len();
        let len = n + 2 * self.pad;
        // The pads stay zero: only the box is written.
        gathered.resize(D * len, 0.0);
        product.resize(D * n, 0.0);
        for k in 0..D {
            gathered[k * len + self.pad..k * len + self.pad + n]
                .par_chunks_mut(1024)
                .zip(self.row_at.par_chunks(1024))
                .for_each(|(z, rows)| {
                    for (z, &row) in z.iter_mut().zip(rows) {
                        *z = match row {
                            u32::MAX => 0.0,
                            row => zeta[row as usize * D + k],
                        };
                    }
                });
        }
        let entries = self.offset.len();
        let gathered = &gathered[..];
        product
            .par_chunks_mut(GROUP * D * LANES)
            .zip(self.value.par_chunks(GROUP * entries * LANES))
            .enumerate()
            .for_each(|(g, (y, value))| {
                self.lanes.wide(
                    #[inline(always)]
                    || {
                        let chunks = y.chunks_exact_mut(D * LANES);
                        for (c, (y, value)) in
                            chunks.zip(value.chunks_exact(entries * LANES)).enumerate()
                        {
                            let c = g * GROUP + c;
                            if self.occupied[c] {
                                let base = self.pad + c * LANES;
                                chunk_product::<D>(value, &self.offset, gathered, len, base, y);
                            }
                        }
                    },
                );
            });
        out.par_chunks_exact_mut(D)
            .zip(self.position.par_iter())
            .for_each(|(o, &p)| {
                let (c, i) = (p as usize / LANES, p as usize % LANES);
                for (k, o) in o.iter_mut().enumerate() {
                    *o = product[(c * D + k) * LANES + i];
                }
            });
    }
}

/// One chunk of [`LatticeRows::apply`]: `y[k · LANES + i] = Σ_e value[e · LANES + i]
/// ζ_k[base + i + offset_e]`, summed in ascending `e` from zero.
#[inline(always)]
fn chunk_product<const D: usize>(
    value: &[f64],
    offset: &[isize],
    gathered: &[f64],
    len: usize,
    base: usize,
    y: &mut [f64],
) {
    let mut sum = [[0.0; LANES]; D];
    for (v, &o) in value.chunks_exact(LANES).zip(offset) {
        let v: &[f64; LANES] = v.try_into().expect("a chunk");
        let start = (base as isize + o) as usize;
        for (k, sum) in sum.iter_mut().enumerate() {
            let z: &[f64; LANES] = gathered[k * len + start..k * len + start + LANES]
                .try_into()
                .expect("a chunk");
            for i in 0..LANES {
                sum[i] += v[i] * z[i];
            }
        }
    }
    for (k, sum) in sum.iter().enumerate() {
        y[k * LANES..(k + 1) * LANES].copy_from_slice(sum);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Packed rows: entries per row, their columns and values (`block` of room per row).
    type Packed = (Vec<u32>, Vec<u32>, Vec<f64>);

    /// A value in [-1, 1) from a counter (a fixed sequence, no generator needed).
    fn value(i: u64) -> f64 {
        let x = i.wrapping_mul(0x9E37_79B9_7F4A_7C15).rotate_left(29) >> 11;
        x as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// Packed rows on the lattice points of a ball cut by its box (which it fills to about
    /// 0.6 in 3D), with rows missing inside it too, every neighbour within `radius` an entry in ascending
    /// order, as the assembly packs them. Returns the indices and the packed rows.
    fn ball<const D: usize>(width: i64, radius: usize) -> (Vec<[i64; D]>, usize, Packed) {
        let span = 2 * radius + 1;
        let block = span.pow(D as u32);
        let mut index = Vec::new();
        let total = width.pow(D as u32);
        for n in 0..total {
            let i: [i64; D] = std::array::from_fn(|a| (n / width.pow(a as u32)) % width);
            let r2: i64 = i.iter().map(|&x| (2 * x - width + 1).pow(2)).sum();
            // A ball cut by its box, with single points missing inside.
            if 2 * r2 <= 3 * width * width && n % 7 != 3 {
                index.push(i);
            }
        }
        // The slots in a scrambled order, as the active nodes are (first touched first).
        index.sort_by_key(|i| (i.iter().sum::<i64>() * 7919) % 101);
        let slot_of = |i: [i64; D]| index.iter().position(|&j| j == i);
        let (mut count, mut column) = (vec![0; index.len()], vec![0; index.len() * block]);
        let mut packed = vec![0.0; index.len() * block];
        for (row, &i) in index.iter().enumerate() {
            let mut k = 0;
            for e in 0..block {
                let j: [i64; D] = std::array::from_fn(|a| {
                    i[a] + ((e / span.pow(a as u32)) % span) as i64 - radius as i64
                });
                if let Some(col) = slot_of(j) {
                    column[row * block + k] = col as u32;
                    packed[row * block + k] = value((row * block + e) as u64);
                    k += 1;
                }
            }
            count[row] = k as u32;
        }
        (index, block, (count, column, packed))
    }

    /// The packed rows' product, as `NodeOperator::apply` takes it at order 1.
    fn packed_product<const D: usize>(
        block: usize,
        (count, column, packed): (&[u32], &[u32], &[f64]),
        zeta: &[f64],
    ) -> Vec<f64> {
        let mut out = vec![0.0; count.len() * D];
        for (row, o) in out.chunks_exact_mut(D).enumerate() {
            let mut sum = [0.0; D];
            for k in row * block..row * block + count[row] as usize {
                let z = &zeta[column[k] as usize * D..];
                for a in 0..D {
                    sum[a] += packed[k] * z[a];
                }
            }
            o.copy_from_slice(&sum);
        }
        out
    }

    fn same_products<const D: usize>(width: i64, radius: usize) {
        let (index, block, (count, column, packed)) = ball::<D>(width, radius);
        let rows = (&count[..], &column[..], &packed[..]);
        let zeta: Vec<f64> = (0..index.len() * D).map(|i| value(i as u64 + 5)).collect();
        let expected = packed_product::<D>(block, rows, &zeta);
        for lanes in [Lanes::baseline(), Lanes::detect()] {
            let lattice =
                LatticeRows::new(&index, radius, block, rows, lanes, Vec::new()).expect("laid out");
            let mut out = vec![f64::NAN; zeta.len()];
            // Twice: the scratch of the first product must not leak into the second.
            lattice.apply::<D>(&zeta, &mut out);
            lattice.apply::<D>(&zeta, &mut out);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&out), bits(&expected), "{D}D, radius {radius}");
        }
    }

    /// The same bits as the packed rows, on a ball with missing points inside, 2D and 3D, the
    /// radii of the quadratic and cubic B-splines, baseline and vector code.
    #[test]
    fn lattice_products_are_the_packed_ones() {
        same_products::<2>(23, 2);
        same_products::<2>(17, 3);
        same_products::<3>(11, 2);
        same_products::<3>(9, 3);
    }

    /// Rows that fill too little of their box, or whose entries are not in ascending order
    /// (the sums' order would change), stay packed.
    #[test]
    fn sparse_or_unordered_rows_stay_packed() {
        let (index, block, (count, mut column, packed)) = ball::<2>(15, 2);
        let rows = (&count[..], &column[..], &packed[..]);
        assert!(LatticeRows::new(&index, 2, block, rows, Lanes::baseline(), Vec::new()).is_some());
        let corners = [[0, 0], [40, 0], [0, 40], [40, 40]];
        let far: Vec<[i64; 2]> = index.iter().copied().chain(corners).collect();
        let mut far_count = count.clone();
        far_count.extend([0; 4]);
        let mut far_column = column.clone();
        far_column.extend(vec![0; 4 * block]);
        let mut far_packed = packed.clone();
        far_packed.extend(vec![0.0; 4 * block]);
        let far_rows = (&far_count[..], &far_column[..], &far_packed[..]);
        assert!(
            LatticeRows::new(&far, 2, block, far_rows, Lanes::baseline(), Vec::new()).is_none()
        );
        column.swap(0, 1);
        let swapped = (&count[..], &column[..], &packed[..]);
        assert!(
            LatticeRows::new(&index, 2, block, swapped, Lanes::baseline(), Vec::new()).is_none()
        );
    }
}
