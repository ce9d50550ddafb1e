//! Human- and machine-readable reports: terminal text, Markdown, JSON and plots of the
//! residual against each named cause's diagnostic variable, before and after the extension.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::cause::Cause;
use crate::error::IdentError;
use crate::ident::{Identification, Report};

/// The JSON report: the fields first (`causes`, `baseline_rmse`, `extended_rmse`,
/// `gain_pct`, `candidates`), then the details.
pub fn json(report: &Report) -> String {
    serde_json::to_string_pretty(report).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}

fn causes_line(r: &Report) -> String {
    r.causes
        .iter()
        .map(|c| c.name())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The terminal summary: what is wrong, where, the causes with evidence, the extension and
/// the held-out gain.
pub fn text(r: &Report) -> String {
    let mut s = String::new();
    let u = &r.unit;
    s.push_str(&format!(
        "ocm ident: {} ({} data, {} rows: {} train / {} held out; split: {})\n",
        r.source,
        r.kind.name(),
        r.rows[0],
        r.rows[1],
        r.rows[2],
        r.split
    ));
    s.push_str(&format!("conventions: {}\n", r.conventions));
    s.push_str(&format!("baseline: {}\n", r.baseline));
    for p in &r.baseline_params {
        s.push_str(&format!(
            "  {:<28} {:>12.5e} +- {:.2e}\n",
            p.name, p.value, p.std_err
        ));
    }
    s.push_str(&format!(
        "\nwhat the model gets wrong: held-out RMSE {:.4e} {u}\n",
        r.baseline_rmse
    ));
    if let Some(d) = r.dynamic_baseline_rmse {
        s.push_str(&format!(
            "  (linear-dynamic reference model: {d:.4e} {u})\n"
        ));
    }
    for h in &r.hotspots {
        s.push_str(&format!(
            "  largest where {} in [{:.4}, {:.4}]: RMSE {:.4e} {u} ({:.2}x overall)\n",
            h.input, h.from, h.to, h.rmse, h.ratio
        ));
    }
    s.push_str(&format!(
        "  noise RMS estimated from the data: {:.3e} {u} ({})\n",
        r.noise_rmse, r.noise_method
    ));
    for t in &r.direction_tests {
        s.push_str(&format!(
            "  direction test ({} against the motion of {}): {:+.4e} {u} +- {:.1e} at equal inputs over {} cells, {}\n",
            t.output,
            t.state,
            t.effect,
            t.std_err,
            t.cells,
            if t.flips {
                "flips with the direction (friction, not a static map of the inputs)"
            } else {
                "no flip"
            }
        ));
    }
    s.push_str(&format!("\ncause(s): {}\n", causes_line(r)));
    s.push_str(&format!("verdict: {}\n", r.verdict));
    for w in &r.warnings {
        s.push_str(&format!("warning: {w}\n"));
    }
    for c in &r.causes {
        s.push_str(&format!("  {}: {}\n", c.name(), c.definition()));
    }
    s.push_str("\ncandidates (held-out gain %, score = -dBIC, F-test p, held-out HAC t):\n");
    for c in &r.candidates {
        s.push_str(&format!(
            "  {:<16} {:>8.2} {:>12.1} {:>10.2e} {:>8.2} {}\n",
            c.cause.name(),
            c.gain_pct,
            c.score,
            c.p_value,
            c.t_stat,
            if c.accepted {
                "passes"
            } else if c.ill_conditioned {
                "ill-conditioned"
            } else {
                ""
            }
        ));
    }
    s.push_str("\nevidence (residual diagnostics on held-out rows):\n");
    for d in &r.diagnostics {
        s.push_str(&format!(
            "  {:<16} {:<55} {:>10.4}  {}\n",
            d.cause.name(),
            d.statistic,
            d.value,
            d.reading
        ));
    }
    if !r.extensions.is_empty() {
        s.push_str("\nextension(s):\n");
        for e in &r.extensions {
            s.push_str(&format!("  {e}\n"));
        }
        for p in &r.extension_params {
            s.push_str(&format!(
                "  {:<44} {:>12.5e} +- {:.2e}\n",
                p.name, p.value, p.std_err
            ));
        }
    }
    s.push_str(&format!(
        "\nheld-out RMSE: baseline {:.4e} {u} -> extended {:.4e} {u}, gain {:.1} %\n",
        r.baseline_rmse, r.extended_rmse, r.gain_pct
    ));
    s
}

/// The Markdown report, linking the plots written beside it.
pub fn markdown(r: &Report, plots: &[PathBuf]) -> String {
    let mut s = String::new();
    s.push_str(&format!("# ocm ident: {}\n\n", r.source));
    s.push_str(&format!(
        "Kind `{}`, {} rows ({} training, {} held out; {}).\n\n",
        r.kind.name(),
        r.rows[0],
        r.rows[1],
        r.rows[2],
        r.split
    ));
    s.push_str(&format!(
        "**Cause(s): {}.** Held-out RMSE {:.4e} {} (baseline) -> {:.4e} {} (extended), gain **{:.1} %**.\n\n",
        causes_line(r),
        r.baseline_rmse,
        r.unit,
        r.extended_rmse,
        r.unit,
        r.gain_pct
    ));
    s.push_str(&format!(
        "Verdict: {}\n\nNoise RMS estimated from the data: {:.3e} {} ({}). Conventions: {}.\n\n",
        r.verdict, r.noise_rmse, r.unit, r.noise_method, r.conventions
    ));
    for w in &r.warnings {
        s.push_str(&format!("- **warning**: {w}\n"));
    }
    if !r.warnings.is_empty() {
        s.push('\n');
    }
    s.push_str(&format!(
        "## Baseline\n\n{}\n\n| parameter | value | std. error |\n|---|---|---|\n",
        r.baseline
    ));
    for p in &r.baseline_params {
        s.push_str(&format!(
            "| {} | {:.5e} | {:.2e} |\n",
            p.name, p.value, p.std_err
        ));
    }
    if let Some(d) = r.dynamic_baseline_rmse {
        s.push_str(&format!(
            "\nLinear-dynamic reference model: held-out RMSE {d:.4e} {}.\n",
            r.unit
        ));
    }
    s.push_str(
        "\n## Where the baseline is wrong\n\n| input bin | RMSE | x overall |\n|---|---|---|\n",
    );
    for h in &r.hotspots {
        s.push_str(&format!(
            "| {} in [{:.4}, {:.4}] | {:.4e} | {:.2} |\n",
            h.input, h.from, h.to, h.rmse, h.ratio
        ));
    }
    s.push_str("\n## Candidates\n\nScore is -dBIC on training rows; a cause passes with dBIC below -margin, held-out gain above the minimum and an F-test p-value below alpha / (number of candidates); an ill-conditioned fit never passes.\n\n| cause | definition | held-out gain % | score | F p-value | HAC t | passes |\n|---|---|---|---|---|---|---|\n");
    for c in &r.candidates {
        s.push_str(&format!(
            "| {} | {} | {:.2} | {:.1} | {:.2e} | {:.2} | {} |\n",
            c.cause.name(),
            c.cause.definition(),
            c.gain_pct,
            c.score,
            c.p_value,
            c.t_stat,
            if c.accepted { "yes" } else { "no" }
        ));
    }
    if !r.additions.is_empty() {
        s.push_str("\nFurther causes tried on top of the named ones (held-out gain over the current extension):\n\n");
        for c in &r.additions {
            s.push_str(&format!("- {}: {:.2} %\n", c.cause.name(), c.gain_pct));
        }
    }
    s.push_str("\n## Evidence\n\n| cause | statistic | value | reading |\n|---|---|---|---|\n");
    for d in &r.diagnostics {
        s.push_str(&format!(
            "| {} | {} | {:.4} | {} |\n",
            d.cause.name(),
            d.statistic,
            d.value,
            d.reading
        ));
    }
    if !r.extensions.is_empty() {
        s.push_str("\n## Extension\n\n");
        for e in &r.extensions {
            s.push_str(&format!("- {e}\n"));
        }
        s.push_str("\n| parameter | value | std. error |\n|---|---|---|\n");
        for p in &r.extension_params {
            s.push_str(&format!(
                "| {} | {:.5e} | {:.2e} |\n",
                p.name, p.value, p.std_err
            ));
        }
    }
    if !plots.is_empty() {
        s.push_str("\n## Plots\n\n");
        for p in plots {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            s.push_str(&format!("![{name}]({name})\n"));
        }
    }
    s
}

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // Registration fails only for malformed font bytes; plots then lack labels.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

/// Writes the plots: first `timeline.png` (measured, baseline and extended model over time on a
/// held-out window), then per named cause the held-out residual (of the output channel the
/// extension improves most) against the cause's diagnostic variable, before (grey) and after
/// (blue), and for hysteresis and friction the loops (output against the drive or the moving
/// state: measured, baseline, extended).
pub fn plots(id: &Identification, dir: &Path) -> Result<Vec<PathBuf>, IdentError> {
    register_font();
    let mut out = Vec::new();
    let rows: Vec<usize> = (0..id.test.len()).filter(|&i| id.test[i]).collect();
    // thin long records so that a plot stays light
    let step = (rows.len() / 5000).max(1);
    let rows: Vec<usize> = rows.into_iter().step_by(step).collect();
    let pc = id.plot_channel;
    let unit = &id.report.unit;
    let y = &id.measured[pc];
    let base: Vec<f64> = y
        .iter()
        .zip(&id.residual_before[pc])
        .map(|(a, e)| a - e)
        .collect();
    let ext: Vec<f64> = y
        .iter()
        .zip(&id.residual_after[pc])
        .map(|(a, e)| a - e)
        .collect();
    // First: measured, baseline and extended over time on the held-out block where the baseline
    // misses most (at most 1500 rows around its worst row).
    if let Some(worst) = rows.iter().copied().max_by(|&a, &b| {
        id.residual_before[pc][a]
            .abs()
            .total_cmp(&id.residual_before[pc][b].abs())
    }) {
        let (mut a, mut b) = (worst, worst);
        // one trial: stop where time goes backwards
        while a > 0 && id.test[a - 1] && id.time_s[a - 1] < id.time_s[a] && worst - a < 750 {
            a -= 1;
        }
        while b + 1 < y.len()
            && id.test[b + 1]
            && id.time_s[b + 1] > id.time_s[b]
            && b - worst < 750
        {
            b += 1;
        }
        let t = &id.time_s;
        let series: Vec<Curve> = vec![
            (
                "measured",
                RGBColor(0, 0, 0),
                (a..=b).map(|i| (t[i], y[i])).collect(),
            ),
            (
                "baseline",
                RGBColor(150, 150, 150),
                (a..=b).map(|i| (t[i], base[i])).collect(),
            ),
            (
                "extended",
                RGBColor(0, 0, 255),
                (a..=b).map(|i| (t[i], ext[i])).collect(),
            ),
        ];
        let path = dir.join("timeline.png");
        draw_lines(
            &path,
            &series,
            "time [s]",
            &format!("{} [{unit}]", id.outputs[pc]),
            "held-out window: measured, baseline and extended model",
        )
        .map_err(|e| IdentError::Invalid(format!("{}: plot failed: {e}", path.display())))?;
        out.push(path);
    }
    for (cause, var, label) in &id.variables {
        let name = if *cause == Cause::None {
            "residual"
        } else {
            cause.name()
        };
        let path = dir.join(format!("residual_vs_{name}.png"));
        let before: Vec<(f64, f64)> = rows
            .iter()
            .map(|&i| (var[i], id.residual_before[pc][i]))
            .collect();
        let after: Vec<(f64, f64)> = rows
            .iter()
            .map(|&i| (var[i], id.residual_after[pc][i]))
            .collect();
        draw(
            &path,
            &before,
            &after,
            label,
            &format!("residual of {} [{}]", id.outputs[pc], id.report.unit),
            cause.name(),
        )
        .map_err(|e| IdentError::Invalid(format!("{}: plot failed: {e}", path.display())))?;
        out.push(path);
        if matches!(cause, Cause::Hysteresis | Cause::Friction) {
            // loops: output against the drive (or the moving state), baseline and extended
            let (lv, ll) = &id.loop_variable;
            let pts =
                |p: &[f64]| -> Vec<(f64, f64)> { rows.iter().map(|&i| (lv[i], p[i])).collect() };
            let series = vec![
                ("measured", RGBColor(0, 0, 0), pts(y)),
                ("baseline", RGBColor(150, 150, 150), pts(&base)),
                ("extended", RGBColor(0, 0, 255), pts(&ext)),
            ];
            let path = dir.join(format!("loops_{}.png", cause.name()));
            draw_points(
                &path,
                &series,
                ll,
                &format!("{} [{unit}]", id.outputs[pc]),
                cause.name(),
            )
            .map_err(|e| IdentError::Invalid(format!("{}: plot failed: {e}", path.display())))?;
            out.push(path);
        }
    }
    Ok(out)
}

/// A named, coloured set of points.
type Curve<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);
type Series<'a> = [Curve<'a>];

fn bounds(series: &Series) -> (f64, f64, f64, f64) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (_, _, pts) in series {
        for p in pts.iter().filter(|p| p.0.is_finite() && p.1.is_finite()) {
            x0 = x0.min(p.0);
            x1 = x1.max(p.0);
            y0 = y0.min(p.1);
            y1 = y1.max(p.1);
        }
    }
    if x0.partial_cmp(&x1) != Some(std::cmp::Ordering::Less) {
        x1 = x0 + 1.0;
    }
    if y0.partial_cmp(&y1) != Some(std::cmp::Ordering::Less) {
        y1 = y0 + 1.0;
    }
    (x0, x1, y0, y1)
}

fn draw_lines(
    path: &Path,
    series: &Series,
    xlabel: &str,
    ylabel: &str,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let (x0, x1, y0, y1) = bounds(series);
    let root = BitMapBackend::new(path, (1000, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(ylabel)
        .draw()?;
    for (name, color, pts) in series {
        let c = *color;
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(())
}

fn draw_points(
    path: &Path,
    series: &Series,
    xlabel: &str,
    ylabel: &str,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let (x0, x1, y0, y1) = bounds(series);
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("held-out loops: {title}"), ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(ylabel)
        .draw()?;
    for (name, color, pts) in series {
        let c = *color;
        chart
            .draw_series(pts.iter().map(|p| Circle::new(*p, 1, c.mix(0.6).filled())))?
            .label(*name)
            .legend(move |(x, y)| Circle::new((x, y), 4, c.filled()));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(())
}

fn draw(
    path: &Path,
    before: &[(f64, f64)],
    after: &[(f64, f64)],
    xlabel: &str,
    ylabel: &str,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let finite = |v: &&(f64, f64)| v.0.is_finite() && v.1.is_finite();
    let all: Vec<&(f64, f64)> = before.iter().chain(after).filter(finite).collect();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in &all {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    if x0.partial_cmp(&x1) != Some(std::cmp::Ordering::Less) {
        x1 = x0 + 1.0;
    }
    if y0.partial_cmp(&y1) != Some(std::cmp::Ordering::Less) {
        y1 = y0 + 1.0;
    }
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("held-out residual vs diagnostic variable: {title}"),
            ("sans-serif", 22),
        )
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(ylabel)
        .draw()?;
    chart
        .draw_series(
            before
                .iter()
                .filter(finite)
                .map(|p| Circle::new(*p, 2, RGBColor(150, 150, 150).filled())),
        )?
        .label("baseline")
        .legend(|(x, y)| Circle::new((x, y), 4, RGBColor(150, 150, 150).filled()));
    chart
        .draw_series(
            after
                .iter()
                .filter(finite)
                .map(|p| Circle::new(*p, 2, BLUE.mix(0.6).filled())),
        )?
        .label("extended")
        .legend(|(x, y)| Circle::new((x, y), 4, BLUE.filled()));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(())
}

/// Writes `report.md`, `report.json` and the plots into `dir`; returns the files written.
pub fn write_all(id: &Identification, dir: &Path) -> Result<Vec<PathBuf>, IdentError> {
    std::fs::create_dir_all(dir).map_err(|e| IdentError::Io {
        file: dir.display().to_string(),
        source: e,
    })?;
    let plots = plots(id, dir)?;
    let md = dir.join("report.md");
    let js = dir.join("report.json");
    let io = |p: &Path| {
        let f = p.display().to_string();
        move |e| IdentError::Io { file: f, source: e }
    };
    std::fs::write(&md, markdown(&id.report, &plots)).map_err(io(&md))?;
    std::fs::write(&js, json(&id.report)).map_err(io(&js))?;
    let mut files = vec![md, js];
    files.extend(plots);
    Ok(files)
}
