//! The two SVG figures of `docs/accuracy.md`: PSNR against time and against size, one panel
//! per image, with the Pareto front named and the default ringed (plotters, SVG backend).

use anyhow::Result;
use plotters::prelude::*;

use crate::choice::FAMILIES;
use crate::measure::{ImageResult, Measured};
use crate::pareto::{Axis, pareto};
use crate::sweep::{Defaults, is_default};

pub const PALETTE: [RGBColor; 11] = [
    RGBColor(31, 119, 180),
    RGBColor(23, 190, 207),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(127, 127, 127),
    RGBColor(148, 103, 189),
    RGBColor(227, 119, 194),
    RGBColor(140, 86, 75),
    RGBColor(188, 189, 34),
    RGBColor(20, 40, 110),
];

/// than four, only powers of ten when it gives more than twelve.
pub fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let sets: [&[f64]; 4] = [
        &[1.0],
        &[1.0, 2.0, 5.0],
        &[1.0, 1.5, 2.0, 3.0, 5.0, 7.0],
        &[1.0, 1.2, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0, 6.0, 8.0],
    ];
    let ticks = |set: &[f64]| -> Vec<f64> {
        let mut v = Vec::new();
        let mut decade = 10f64.powf(lo.log10().floor());
        while decade <= hi {
            v.extend(set.iter().map(|m| m * decade).filter(|t| *t >= lo && *t <= hi));
            decade *= 10.0;
        }
        v
    };
    let one_two_five = ticks(sets[1]);
    if one_two_five.len() > 12 {
        return ticks(sets[0]);
    }
    sets[1..].iter().map(|s| ticks(s)).find(|t| t.len() >= 4).unwrap_or_else(|| ticks(sets[3]))
}

pub fn tick_label(v: f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Places labels next to points without covering each other (greedy, in pixels).
pub struct Placer {
    pub area: (std::ops::Range<i32>, std::ops::Range<i32>),
    pub labels: Vec<(i32, i32, i32, i32)>,
    pub points: Vec<(i32, i32)>,
}

impl Placer {
    /// Offset of the label's top-left corner from `at`.
    /// Estimated width of a label in pixels (plotters writes an 11-point label as 8.9-pixel
    /// sans-serif).
    pub fn width(&self, text: &str) -> i32 {
        (text.chars().count() as f64 * 5.1) as i32 + 2
    }

    pub fn place(&mut self, at: (i32, i32), text: &str) -> (i32, i32) {
        let (w, h) = (self.width(text), 11);
        let candidates = [
            (8, -6),
            (7, -15),
            (7, 3),
            (-w - 8, -6),
            (-w - 7, -15),
            (-w - 7, 3),
            (-w / 2, -20),
            (-w / 2, 8),
            (7, -28),
            (7, 16),
            (-w - 7, -28),
            (-w - 7, 16),
            (14, -42),
            (14, 30),
            (-w - 14, -42),
            (-w - 14, 30),
        ];
        let cost = |(dx, dy): (i32, i32)| -> i32 {
            let (x0, y0) = (at.0 + dx, at.1 + dy);
            let (x1, y1) = (x0 + w, y0 + h);
            let outside = !(self.area.0.contains(&x0)
                && self.area.0.contains(&x1)
                && self.area.1.contains(&y0)
                && self.area.1.contains(&y1));
            let labels = self.labels.iter().filter(|b| x0 < b.2 && b.0 < x1 && y0 < b.3 && b.1 < y1).count() as i32;
            let points =
                self.points.iter().filter(|p| p.0 + 4 > x0 && p.0 - 4 < x1 && p.1 + 4 > y0 && p.1 - 4 < y1).count()
                    as i32;
            100 * outside as i32 + 10 * labels + points
        };
        let best = candidates.iter().copied().min_by_key(|c| cost(*c)).expect("candidates");
        self.labels.push((at.0 + best.0, at.1 + best.1, at.0 + best.0 + w, at.1 + best.1 + h));
        best
    }
}

pub fn plot(results: &[&ImageResult], axis: Axis, d: &Defaults) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1500, 1220)).into_drawing_area();
        root.fill(&WHITE)?;
        let (title, x_desc) = match axis {
            Axis::Time => (
                "Error vs time: PSNR against the float64 reference (all LODs) vs ms per source Mpx (median, 2 cores)",
                "ms per source megapixel, whole split (log scale)",
            ),
            Axis::Size => (
                "Error vs size: PSNR against the float64 reference (all LODs) vs mean payload bytes per 128² tile",
                "KiB per tile (log scale)",
            ),
        };
        let root = root.titled(title, ("sans-serif", 22))?;
        let (legend, rest) = root.split_vertically(40);
        // The legend: families present, the default's ring, the front.
        let present: Vec<usize> = (0..FAMILIES.len())
            .filter(|f| results.iter().any(|r| r.measured.values().any(|m| m.choice.family() == *f)))
            .collect();
        let mut x = 20;
        for &f in &present {
            legend.draw(&Circle::new((x, 20), 5, PALETTE[f].filled()))?;
            legend.draw(&Text::new(FAMILIES[f], (x + 9, 13), ("sans-serif", 13)))?;
            x += 22 + (FAMILIES[f].len() as i32) * 7;
        }
        legend.draw(&Circle::new((x, 20), 8, BLACK.stroke_width(2)))?;
        legend.draw(&Text::new("current default", (x + 12, 13), ("sans-serif", 13)))?;
        x += 130;
        legend.draw(&PathElement::new(vec![(x - 6, 20), (x + 14, 20)], BLACK.stroke_width(1)))?;
        legend.draw(&Text::new("Pareto front (named)", (x + 20, 13), ("sans-serif", 13)))?;

        for (panel, r) in rest.split_evenly((2, 2)).iter().zip(results) {
            let ms: Vec<&Measured> = r.measured.values().collect();
            let pts: Vec<(f64, f64)> = ms.iter().map(|m| (axis.value(m, &r.img), m.plot_psnr())).collect();
            let (xmin, xmax) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.0), b.max(p.0)));
            let (ymin, ymax) = pts.iter().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
            let (x0, x1) = (xmin / 1.3, xmax * 1.8);
            let caption = format!(
                "{} ({}){}",
                r.img.title,
                r.img.key,
                if r.img.has_alpha() { ": colour shown over black" } else { "" }
            );
            let mut chart = ChartBuilder::on(panel)
                .caption(caption, ("sans-serif", 17))
                .margin(14)
                .x_label_area_size(42)
                .y_label_area_size(52)
                .build_cartesian_2d(
                    (x0..x1).log_scale().with_key_points(log_ticks(x0, x1)),
                    (ymin - 2.0).floor()..(ymax + 2.5).ceil(),
                )?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc("PSNR, dB (all LODs)")
                .x_label_formatter(&|v| tick_label(*v))
                .y_label_formatter(&|v| format!("{v:.0}"))
                .label_style(("sans-serif", 12))
                .axis_desc_style(("sans-serif", 13))
                .light_line_style(TRANSPARENT)
                .bold_line_style(RGBColor(228, 228, 228))
                .draw()?;
            let front = pareto(&pts);
            chart.draw_series(LineSeries::new(front.iter().map(|&i| pts[i]), BLACK.stroke_width(1)))?;
            for (i, p) in pts.iter().enumerate() {
                let colour = PALETTE[ms[i].choice.family()];
                let radius = if front.contains(&i) { 5 } else { 3 };
                chart.draw_series(std::iter::once(Circle::new(*p, radius, colour.filled())))?;
            }
            let (xr, yr) = chart.plotting_area().get_pixel_range();
            let mut placer = Placer {
                area: (xr, yr),
                labels: Vec::new(),
                points: pts.iter().map(|p| chart.backend_coord(p)).collect(),
            };
            let mut named: Vec<(usize, String)> = front.iter().map(|&i| (i, ms[i].choice.label())).collect();
            for (i, m) in ms.iter().enumerate() {
                if is_default(m, &r.img, d) {
                    chart.draw_series(std::iter::once(Circle::new(pts[i], 9, BLACK.stroke_width(2))))?;
                    match named.iter_mut().find(|(j, _)| *j == i) {
                        Some((_, label)) => label.push_str(" (default)"),
                        None => named.push((i, format!("{} (default)", m.choice.label()))),
                    }
                }
            }
            for (i, label) in named {
                let offset = placer.place(chart.backend_coord(&pts[i]), &label);
                if offset.1.abs() > 30 {
                    // A label moved far from its point gets a leader line.
                    let end = (if offset.0 < 0 { offset.0 + placer.width(&label) } else { offset.0 }, offset.1 + 6);
                    chart.draw_series(std::iter::once(
                        EmptyElement::at(pts[i]) + PathElement::new(vec![(0, 0), end], RGBColor(120, 120, 120)),
                    ))?;
                }
                chart.draw_series(std::iter::once(
                    EmptyElement::at(pts[i]) + Text::new(label, offset, ("sans-serif", 11).into_font()),
                ))?;
            }
        }
        root.present()?;
    }
    Ok(svg)
}
