//! Piecewise-constant 1D and 2D distributions (pbrt-v3 style) for importance sampling.
//!
//! The GPU integrator reads `func`, `cdf` and `integral` of every [`Distribution1D`] directly,
//! so their meaning is part of the contract:
//! - `func[i]`: the non-negative value of cell i, cells of width 1/n on [0, 1);
//! - `cdf`: n + 1 entries, `cdf[0] = 0`, `cdf[n] = 1`, `cdf[i+1] - cdf[i] = func[i] / (n · integral)`;
//! - `integral`: `sum(func) / n`, the mean of func over [0, 1).
//!
//! When `integral == 0` (all cells zero) the cdf is uniform and the pdf is 1 everywhere; a
//! consumer must apply the same rule instead of dividing by zero.

use crate::mapping::ONE_MINUS_EPSILON;

/// A piecewise-constant distribution on [0, 1) with `func.len()` equal cells.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution1D {
    pub func: Vec<f32>,
    pub cdf: Vec<f32>,
    pub integral: f32,
}

impl Distribution1D {
    /// Builds the distribution of `func`; negative and NaN entries count as 0 so the pdf can
    /// never go negative; an all-zero (or empty) `func` gives the uniform distribution.
    pub fn new(func: &[f32]) -> Self {
        let func: Vec<f32> = if func.is_empty() {
            vec![0.0]
        } else {
            func.iter()
                .map(|&f| if f > 0.0 && f.is_finite() { f } else { 0.0 })
                .collect()
        };
        let n = func.len();
        // Accumulate in f64: a 1024-wide row of values spanning 1e-3 .. 7e4 loses the small
        // cells entirely in f32 running sums.
        let mut running = Vec::with_capacity(n + 1);
        let mut acc = 0.0f64;
        running.push(0.0f64);
        for &f in &func {
            acc += f64::from(f) / n as f64;
            running.push(acc);
        }
        let integral = acc;
        let cdf: Vec<f32> = if integral > 0.0 {
            running.iter().map(|c| (c / integral) as f32).collect()
        } else {
            (0..=n).map(|i| (i as f64 / n as f64) as f32).collect()
        };
        let mut cdf = cdf;
        cdf[n] = 1.0;
        Distribution1D {
            func,
            cdf,
            integral: integral as f32,
        }
    }

    /// Number of cells.
    pub fn count(&self) -> usize {
        self.func.len()
    }

    /// Density of cell `offset` relative to the uniform density on [0, 1).
    fn cell_pdf(&self, offset: usize) -> f32 {
        if self.integral > 0.0 {
            self.func.get(offset).copied().unwrap_or(0.0) / self.integral
        } else {
            1.0
        }
    }

    /// Cell containing `x`, clamped into range (NaN -> 0).
    fn cell_of(&self, x: f32) -> usize {
        let n = self.count();
        ((x * n as f32) as usize).min(n - 1)
    }

    /// Maps a uniform `u` in [0, 1) to (x in [0, 1), pdf(x), cell index).
    ///
    /// The returned x always lies in the returned cell, so `pdf(x)` equals the returned pdf.
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let n = self.count();
        let u = if u >= 0.0 {
            u.min(ONE_MINUS_EPSILON)
        } else {
            0.0
        };
        // Largest i with cdf[i] <= u; as cdf[n] = 1 > u, the cell i has cdf[i+1] > u >= cdf[i],
        // i.e. positive width, so zero-valued cells are never chosen.
        let offset = self
            .cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(n - 1);
        let lo = self.cdf[offset];
        let width = self.cdf[offset + 1] - lo;
        let mut du = u - lo;
        if width > 0.0 {
            du /= width;
        }
        let du = du.clamp(0.0, ONE_MINUS_EPSILON);
        let x = keep_in_cell((offset as f32 + du) / n as f32, offset, n);
        (x, self.cell_pdf(offset), offset)
    }

    /// Density at `x` in [0, 1) (values outside are clamped to the border cells).
    pub fn pdf(&self, x: f32) -> f32 {
        self.cell_pdf(self.cell_of(x))
    }
}

/// Nudges `x` by ulps until `floor(x * n) == offset`: rounding in `(offset + du) / n` can
/// otherwise land on the neighbouring cell, whose pdf may differ by orders of magnitude.
fn keep_in_cell(mut x: f32, offset: usize, n: usize) -> f32 {
    x = x.clamp(0.0, ONE_MINUS_EPSILON);
    for _ in 0..8 {
        let cell = ((x * n as f32) as usize).min(n - 1);
        if cell > offset && x > 0.0 {
            x = f32::from_bits(x.to_bits() - 1);
        } else if cell < offset {
            x = f32::from_bits(x.to_bits() + 1);
        } else {
            break;
        }
    }
    x
}

/// A piecewise-constant distribution on [0, 1)² with `width` x `height` cells: one
/// conditional [`Distribution1D`] over u per row, and a marginal over rows (v) whose
/// `func[row]` is that row's conditional `integral`.
#[derive(Clone, Debug, PartialEq)]
pub struct Distribution2D {
    pub conditional: Vec<Distribution1D>,
    pub marginal: Distribution1D,
}

impl Distribution2D {
    /// `func` is row-major, `width * height` values; missing values count as 0 and extra
    /// values are ignored, and zero sizes are raised to 1, so no input can panic here.
    pub fn new(func: &[f32], width: usize, height: usize) -> Self {
        let width = width.max(1);
        let height = height.max(1);
        let conditional: Vec<Distribution1D> = (0..height)
            .map(|row| {
                let start = (row * width).min(func.len());
                let end = ((row + 1) * width).min(func.len());
                let mut cells = func[start..end].to_vec();
                cells.resize(width, 0.0);
                Distribution1D::new(&cells)
            })
            .collect();
        let row_weights: Vec<f32> = conditional.iter().map(|c| c.integral).collect();
        let marginal = Distribution1D::new(&row_weights);
        Distribution2D {
            conditional,
            marginal,
        }
    }

    /// Maps uniform `u` to (uv, pdf in uv) with the marginal picking v and the row's
    /// conditional picking u.
    pub fn sample_continuous(&self, u: [f32; 2]) -> ([f32; 2], f32) {
        let (v, _, row) = self.marginal.sample_continuous(u[1]);
        let (x, _, col) = self.conditional[row].sample_continuous(u[0]);
        ([x, v], self.cell_pdf(col, row))
    }

    /// Density in uv at `uv` (clamped into [0, 1)²).
    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        let row = self.marginal.cell_of(uv[1]);
        let col = self.conditional[row].cell_of(uv[0]);
        self.cell_pdf(col, row)
    }

    /// func / marginal integral, i.e. p(u | v) · p(v) without the intermediate rounding, so
    /// `sample_continuous` and `pdf` agree exactly.
    fn cell_pdf(&self, col: usize, row: usize) -> f32 {
        let cond = &self.conditional[row];
        if self.marginal.integral > 0.0 {
            cond.func.get(col).copied().unwrap_or(0.0) / self.marginal.integral
        } else {
            // Entirely zero: both levels are uniform.
            1.0
        }
    }
}
