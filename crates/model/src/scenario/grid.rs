//! The cell lattice a scenario defines (docs/model.md §1).

use serde::Serialize;

/// The cell lattice (docs/model.md §1): centres at `x_min + i·Δ`, both walls included.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Grid {
    /// Cells along x (both walls included).
    pub nx: usize,
    /// Cells along y (both walls included).
    pub ny: usize,
    /// x of the first column of centres: the west wall (m).
    pub x_min: f64,
    /// y of the first row of centres: the south wall (m).
    pub y_min: f64,
    /// Δ, the spacing of centres along x and y (m).
    pub resolution_m: f64,
}

impl Grid {
    /// Cells of the grid, occupied ones included.
    pub fn cells(&self) -> usize {
        self.nx * self.ny
    }
    /// Flat index of cell (i, j); i runs along x, j along y (the paper's C_{i,j}).
    #[inline]
    pub fn index(&self, i: usize, j: usize) -> usize {
        i * self.ny + j
    }
    /// Cell (i, j) of a flat index (the inverse of [`Grid::index`]).
    #[inline]
    pub fn cell_of(&self, index: usize) -> (usize, usize) {
        (index / self.ny, index % self.ny)
    }
    /// q^Δ_{i,j}, the horizontal centre of cell (i, j) (paper eq. 8).
    #[inline]
    pub fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.x_min + i as f64 * self.resolution_m,
            self.y_min + j as f64 * self.resolution_m,
        ]
    }
    fn x_max(&self) -> f64 {
        self.x_min + (self.nx - 1) as f64 * self.resolution_m
    }
    fn y_max(&self) -> f64 {
        self.y_min + (self.ny - 1) as f64 * self.resolution_m
    }
    /// The cell whose centre is nearest to (x, y), or `None` outside the room.
    pub fn snap(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let slack = 1e-9 * self.resolution_m.max(1.0);
        if !x.is_finite() || !y.is_finite() {
            return None;
        }
        if x < self.x_min - slack || x > self.x_max() + slack {
            return None;
        }
        if y < self.y_min - slack || y > self.y_max() + slack {
            return None;
        }
        let i = ((x - self.x_min) / self.resolution_m).round() as usize;
        let j = ((y - self.y_min) / self.resolution_m).round() as usize;
        Some((i.min(self.nx - 1), j.min(self.ny - 1)))
    }
}
