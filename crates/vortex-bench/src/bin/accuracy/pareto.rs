//! Error against cost: the two cost axes (time per source megapixel, bytes per tile) and the
//! Pareto front of a set of (cost, PSNR) points, shared by the plots and the tables.

use crate::images::Img;
use crate::measure::Measured;

#[derive(Clone, Copy, PartialEq)]
pub enum Axis {
    Time,
    Size,
}

impl Axis {
    pub fn value(self, m: &Measured, img: &Img) -> f64 {
        match self {
            Axis::Time => m.ms_per_mpx(img),
            Axis::Size => m.bytes_per_tile / 1024.0,
        }
    }

    pub fn describe(self, v: f64) -> String {
        match self {
            Axis::Time => format!("{v:.0} ms/Mpx"),
            Axis::Size => format!("{v:.1} KiB"),
        }
    }
}

/// Indices into `points` (x, y) of the Pareto front, cheapest first: the points that no other
/// point beats on both axes (smaller or equal x with larger y).
pub fn pareto(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].0.total_cmp(&points[b].0).then(points[b].1.total_cmp(&points[a].1)));
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in order {
        if points[i].1 > best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}
