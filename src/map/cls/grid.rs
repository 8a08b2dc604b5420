//! Export of a CLS map as an occupancy grid in the ROS `map_server` format:
//! a binary PGM (P5) image and a YAML description.
//!
//! Cells whose centre is inside the explored region are free, cells crossed
//! by an actual segment are occupied, everything else is unknown. With
//! `negate: 0` map_server reads a pixel value `v` as occupancy
//! `(255 − v) / 255`: 0 (black) is occupied (> 0.65), 254 is free
//! (< 0.196) and 205 lies between the thresholds, hence unknown.

use std::path::{Path, PathBuf};

use super::cls_map::ClsMap;

/// Pixel value of a free cell.
pub const FREE: u8 = 254;
/// Pixel value of an occupied cell.
pub const OCCUPIED: u8 = 0;
/// Pixel value of an unknown cell.
pub const UNKNOWN: u8 = 205;

/// Largest grid accepted (cells): 10⁸ bytes of image.
const MAX_CELLS: usize = 100_000_000;

/// Grid parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridConfig {
    /// Cell side (m). Default 0.05, map_server's usual value.
    pub resolution: f64,
    /// Unknown border around the map (m). Default 0.5.
    pub margin: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        GridConfig {
            resolution: 0.05,
            margin: 0.5,
        }
    }
}

/// An occupancy grid; row 0 is the bottom row (smallest y).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    pub width: usize,
    pub height: usize,
    /// Cell side (m).
    pub resolution: f64,
    /// Map-frame position of the lower-left corner of cell (0, 0) (m).
    pub origin: [f64; 2],
    /// Row-major pixel values, bottom row first.
    pub cells: Vec<u8>,
}

/// Why a grid could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum GridError {
    #[error("resolution {0} m is not a positive finite number")]
    Resolution(f64),
    #[error("the grid would have {0:.3e} cells, more than {MAX_CELLS}")]
    TooLarge(f64),
    #[error("{path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl OccupancyGrid {
    /// The value of cell (`col`, `row`), row 0 at the bottom.
    pub fn get(&self, col: usize, row: usize) -> Option<u8> {
        (col < self.width).then(|| self.cells.get(row * self.width + col).copied())?
    }

    /// The cell containing map point `p`.
    pub fn cell_of(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let c = ((p[0] - self.origin[0]) / self.resolution).floor();
        let r = ((p[1] - self.origin[1]) / self.resolution).floor();
        (c >= 0.0 && r >= 0.0 && (c as usize) < self.width && (r as usize) < self.height)
            .then_some((c as usize, r as usize))
    }

    /// The binary PGM image, top row (largest y) first as image viewers and
    /// map_server expect.
    pub fn to_pgm(&self) -> Vec<u8> {
        let mut out = format!("P5\n{} {}\n255\n", self.width, self.height).into_bytes();
        for row in self.cells.chunks(self.width.max(1)).rev() {
            out.extend_from_slice(row);
        }
        out
    }

    /// The map_server YAML naming `image` (a path relative to the YAML).
    pub fn to_yaml(&self, image: &str) -> String {
        format!(
            "image: {image}\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
            self.resolution, self.origin[0], self.origin[1]
        )
    }

    /// Writes `STEM.pgm` and `STEM.yaml` into `dir`.
    pub fn write(&self, dir: &Path, stem: &str) -> Result<(), GridError> {
        let image = format!("{stem}.pgm");
        let write = |path: PathBuf, bytes: &[u8]| {
            crate::files::durable::write_atomically(&path, bytes)
                .map_err(|source| GridError::Io { path, source })
        };
        write(dir.join(&image), &self.to_pgm())?;
        write(
            dir.join(format!("{stem}.yaml")),
            self.to_yaml(&image).as_bytes(),
        )
    }
}

/// Rasterises `map` (see the module documentation).
/// The grid's lower-left corner (m) and its columns and rows (as `f64`:
/// a huge count is not cut short) for `map` at `cfg`, without rendering.
pub fn grid_extent(map: &ClsMap, cfg: &GridConfig) -> ([f64; 2], f64, f64) {
    let res = cfg.resolution;
    let margin = if cfg.margin.is_finite() {
        cfg.margin.max(0.0)
    } else {
        0.0
    };
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for s in map.segments() {
        for p in [s.start(), s.end()] {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
    }
    if lo[0] > hi[0] {
        lo = [0.0, 0.0];
        hi = [0.0, 0.0];
    }
    let origin = [lo[0] - margin, lo[1] - margin];
    let cols = ((hi[0] + margin - origin[0]) / res).ceil().max(1.0);
    let rows = ((hi[1] + margin - origin[1]) / res).ceil().max(1.0);
    (origin, cols, rows)
}

pub fn occupancy_grid(map: &ClsMap, cfg: &GridConfig) -> Result<OccupancyGrid, GridError> {
    let res = cfg.resolution;
    if !(res.is_finite() && res > 0.0) {
        return Err(GridError::Resolution(res));
    }
    let (origin, cols, rows) = grid_extent(map, cfg);
    // Checked in f64 first: a cast of a huge count to usize saturates.
    if cols * rows > MAX_CELLS as f64 {
        return Err(GridError::TooLarge(cols * rows));
    }
    let (width, height) = (cols as usize, rows as usize);
    let cells = width * height;
    let mut grid = OccupancyGrid {
        width,
        height,
        resolution: res,
        origin,
        cells: vec![UNKNOWN; cells],
    };
    // Free space by scanlines through the cell centres; the loops are
    // simple and nested (holes inside outers), so even-odd crossing is the
    // region.
    let mut crossings = Vec::new();
    for row in 0..height {
        let y = origin[1] + (row as f64 + 0.5) * res;
        crossings.clear();
        for s in map.segments() {
            let (a, b) = (s.start(), s.end());
            if (a[1] > y) != (b[1] > y) {
                crossings.push(a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]));
            }
        }
        crossings.sort_by(f64::total_cmp);
        for pair in crossings.chunks_exact(2) {
            let first = ((pair[0] - origin[0]) / res - 0.5).ceil().max(0.0) as usize;
            let last = ((pair[1] - origin[0]) / res - 0.5).floor();
            if last < 0.0 {
                continue;
            }
            let last = (last as usize).min(width - 1);
            for col in first..=last {
                grid.cells[row * width + col] = FREE;
            }
        }
    }
    // Walls: sample each actual segment at a quarter cell.
    for s in map.actual_segments() {
        let (a, b) = (s.start(), s.end());
        let steps = ((s.length() / (0.25 * res)).ceil() as usize).max(1);
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            if let Some((c, r)) = grid.cell_of(p) {
                grid.cells[r * width + c] = OCCUPIED;
            }
        }
    }
    Ok(grid)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A 4 m × 3 m room: the bottom and right walls seen, the rest open.
    fn room() -> ClsMap {
        let pts = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        crate::explore::pursuit::tests::map_of(&pts, &[2, 3])
    }

    #[test]
    fn free_inside_walls_occupied_unknown_outside() {
        let grid = occupancy_grid(&room(), &GridConfig::default()).unwrap();
        assert_eq!((grid.width, grid.height), (100, 80));
        let at = |p: [f64; 2]| {
            let (c, r) = grid.cell_of(p).unwrap();
            grid.get(c, r).unwrap()
        };
        assert_eq!(at([2.0, 1.5]), FREE);
        assert_eq!(at([2.0, 0.0]), OCCUPIED);
        assert_eq!(at([4.0, 1.5]), OCCUPIED);
        // The virtual side at y = 3 is a frontier: free below, unknown above.
        assert_eq!(at([2.0, 2.9]), FREE);
        assert_eq!(at([2.0, 3.2]), UNKNOWN);
        assert_eq!(at([-0.3, 1.0]), UNKNOWN);
    }

    #[test]
    fn pgm_and_yaml_follow_map_server() {
        let grid = occupancy_grid(
            &room(),
            &GridConfig {
                resolution: 0.1,
                margin: 0.0,
            },
        )
        .unwrap();
        let pgm = grid.to_pgm();
        assert!(pgm.starts_with(b"P5\n40 30\n255\n"));
        assert_eq!(pgm.len(), b"P5\n40 30\n255\n".len() + 40 * 30);
        let yaml = grid.to_yaml("map.pgm");
        assert!(yaml.contains("image: map.pgm\n"));
        assert!(yaml.contains("resolution: 0.1\n"));
        assert!(yaml.contains("origin: [0, 0, 0.0]\n"));
        assert!(yaml.contains("negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"));
        assert!(matches!(
            occupancy_grid(
                &room(),
                &GridConfig {
                    resolution: 0.0,
                    margin: 0.0
                }
            ),
            Err(GridError::Resolution(_))
        ));
    }
}
