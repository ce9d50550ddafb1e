//! Line charts written as PNG and SVG side by side.

use std::path::Path;
use std::sync::Once;

use anyhow::{Context, Result};
use plotters::prelude::*;

/// One curve of a chart.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
    /// Draw the points as dots (a cloud) instead of joining them.
    pub dots: bool,
}

/// A chart with labelled axes.
pub struct Chart<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// X axis label, with unit.
    pub x_label: &'a str,
    /// Y axis label, with unit.
    pub y_label: &'a str,
    /// The curves, drawn with a sequential colour map in order.
    pub series: Vec<Series>,
    /// One unit is as long on both axes (maps, trajectories).
    pub equal_axes: bool,
}

/// plotters draws text with a font it is given; we embed DejaVu Sans so the
/// plots need no system fonts.
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // A failure leaves text undrawn but the curves intact; plotters then
        // reports the missing font as a drawing error, which we surface.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

impl Chart<'_> {
    /// Writes `<stem>.png` and `<stem>.svg` into `dir`.
    pub fn write(&self, dir: &Path, stem: &str) -> Result<()> {
        register_font();
        let png = dir.join(format!("{stem}.png"));
        let svg = dir.join(format!("{stem}.svg"));
        self.draw(BitMapBackend::new(&png, (1000, 700)).into_drawing_area())
            .with_context(|| format!("drawing {}", png.display()))?;
        self.draw(SVGBackend::new(&svg, (1000, 700)).into_drawing_area())
            .with_context(|| format!("drawing {}", svg.display()))?;
        Ok(())
    }

    fn draw<DB: DrawingBackend>(&self, area: DrawingArea<DB, plotters::coord::Shift>) -> Result<()>
    where
        DB::ErrorType: 'static,
    {
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow::anyhow!("{e:?}");
        area.fill(&WHITE).map_err(err)?;
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        // finite points only: an axis range at infinity or at f64::MAX (no points at all)
        // sends the tick search into an endless loop
        for p in self
            .series
            .iter()
            .flat_map(|s| &s.points)
            .filter(|p| p.0.is_finite() && p.1.is_finite())
        {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
        if x0 > x1 {
            (x0, x1) = (0.0, 1.0);
        }
        if y0 > y1 {
            (y0, y1) = (0.0, 1.0);
        }
        // a flat series: a unit range above it, or its own scale where that is not resolved
        // beside the value
        if x0 >= x1 {
            x1 = x0 + x0.abs().max(1.0);
        }
        if y0 >= y1 {
            y1 = y0 + y0.abs().max(1.0);
        }
        let mut pad = 0.04 * (y1 - y0);
        if self.equal_axes {
            // The plot area left inside the margins and label areas below.
            let (w, h) = area.dim_in_pixel();
            let (pw, ph) = (
                f64::from(w.saturating_sub(2 * 16 + 72).max(1)),
                f64::from(h.saturating_sub(2 * 16 + 48 + 40).max(1)),
            );
            let scale = ((x1 - x0) / pw).max((y1 - y0 + 2.0 * pad) / ph);
            let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
            (x0, x1) = (cx - 0.5 * scale * pw, cx + 0.5 * scale * pw);
            (y0, y1) = (cy - 0.5 * scale * ph, cy + 0.5 * scale * ph);
            pad = 0.0;
        }
        let mut chart = ChartBuilder::on(&area)
            .caption(self.title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(self.x_label)
            .y_desc(self.y_label)
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(err)?;
        let n = self.series.len().max(2) - 1;
        for (i, s) in self.series.iter().enumerate() {
            let c = ViridisRGB::get_color(i as f64 / n as f64);
            let drawn = if s.dots {
                chart.draw_series(
                    s.points
                        .iter()
                        .map(|&p| Circle::new(p, 2, c.mix(0.6).filled())),
                )
            } else {
                chart.draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
            };
            drawn
                .map_err(err)?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
        area.present().map_err(err)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chart with no points, or with only non-finite ones, is drawn on a unit range (the axis
    /// search looped for ever on the range an empty series left); a flat series gets a range.
    #[test]
    fn empty_flat_and_non_finite_series_are_drawn() {
        let dir = std::env::temp_dir().join(format!("ocm-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cases: [Vec<(f64, f64)>; 4] = [
            vec![],
            vec![(f64::NAN, 1.0), (f64::INFINITY, 2.0)],
            vec![(0.0, 5.0), (1.0, 5.0)],
            vec![(0.0, 1.0), (f64::INFINITY, f64::NEG_INFINITY), (1.0, 2.0)],
        ];
        for (i, points) in cases.into_iter().enumerate() {
            Chart {
                title: "t",
                x_label: "x",
                y_label: "y",
                series: vec![Series {
                    label: "s".into(),
                    points,
                    dots: i % 2 == 0,
                }],
                equal_axes: i == 3,
            }
            .write(&dir, &format!("c{i}"))
            .unwrap();
            assert!(dir.join(format!("c{i}.png")).exists());
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
