//! The loss curve of a training run, as CSV and PNG.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{LearnError, Result};

/// Losses at the end of one epoch.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpochRecord {
    /// Epoch number, from 1.
    pub epoch: usize,
    /// Mean training loss over the epoch's batches (scaled units, dimensionless).
    pub train_loss: f64,
    /// Validation loss after the epoch (NaN when there is no validation set).
    pub val_loss: f64,
    /// Step size of the epoch's last optimiser step (NaN in curves written before it was kept).
    #[serde(default = "not_recorded")]
    pub learning_rate: f64,
    /// Wall time since the start of training, in seconds.
    pub elapsed_s: f64,
}

fn not_recorded() -> f64 {
    f64::NAN
}

/// Writes the curve as CSV with a header line.
pub fn write_csv(path: &Path, curve: &[EpochRecord]) -> Result<()> {
    let io = |e: std::io::Error| LearnError::io(path, e);
    let mut w = csv::Writer::from_path(path).map_err(|e| LearnError::io(path, e.into()))?;
    w.write_record([
        "epoch",
        "train_loss",
        "val_loss",
        "learning_rate",
        "elapsed_s",
    ])
    .map_err(|e| io(e.into()))?;
    for r in curve {
        w.write_record([
            r.epoch.to_string(),
            format!("{:.8e}", r.train_loss),
            format!("{:.8e}", r.val_loss),
            format!("{:.6e}", r.learning_rate),
            format!("{:.3}", r.elapsed_s),
        ])
        .map_err(|e| io(e.into()))?;
    }
    w.flush().map_err(io)
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // Embedded so that plots need no system fonts; a failure shows up as a drawing error.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

type Getter = fn(&EpochRecord) -> f64;

/// Draws training and validation loss against epoch, log scale, as PNG.
pub fn write_png(path: &Path, title: &str, curve: &[EpochRecord]) -> Result<()> {
    register_font();
    let fail = |reason: String| LearnError::Plot {
        path: path.to_path_buf(),
        reason,
    };
    let positive = |v: f64| v.is_finite() && v > 0.0;
    let values: Vec<f64> = curve
        .iter()
        .flat_map(|r| [r.train_loss, r.val_loss])
        .filter(|&v| positive(v))
        .collect();
    if values.is_empty() {
        return Err(fail("no positive finite loss to draw".into()));
    }
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min) * 0.8;
    let hi = values.iter().copied().fold(0.0, f64::max) * 1.25;
    let last = curve.last().map_or(1, |r| r.epoch).max(2) as f64;
    let area = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    let err = |e: DrawingAreaErrorKind<_>| fail(format!("{e:?}"));
    area.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&area)
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(80)
        .build_cartesian_2d(1.0..last, (lo..hi).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("epoch")
        .y_desc("loss (scaled units)")
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(err)?;
    let series: [(&str, RGBColor, Getter); 2] = [
        ("train", BLUE, |r| r.train_loss),
        ("validation", RED, |r| r.val_loss),
    ];
    for (label, colour, get) in series {
        let pts: Vec<(f64, f64)> = curve
            .iter()
            .map(|r| (r.epoch as f64, get(r)))
            .filter(|p| positive(p.1))
            .collect();
        if pts.is_empty() {
            continue;
        }
        chart
            .draw_series(LineSeries::new(pts, colour.stroke_width(2)))
            .map_err(err)?
            .label(label)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
        .map_err(err)?;
    area.present().map_err(err)
}
