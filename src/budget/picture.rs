//! The budget as a picture: per Zernike term (j ≥ 4) a bar as tall as its
//! total 1σ, split by the contributors' shares of the variance (each one's
//! squared contribution over the sum of them; correlations between degrees
//! of freedom move the total, not the split), one colour for each of the six
//! largest contributors and one for the rest; front and back side by side.
//!
//! Text is DejaVu Sans, embedded once in `plot` and registered
//! from there.

use std::path::Path;

use plotters::prelude::*;

use super::table::total_std_nm;
use super::Budget;

use crate::plot::{register_font, FAMILY};
/// Contributors drawn in colours of their own.
pub const TOP: usize = 6;
const COLOURS: [RGBColor; TOP] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];
const REST: RGBColor = RGBColor(180, 180, 180);

/// What went wrong drawing the picture.
#[derive(Debug, thiserror::Error)]
pub enum PictureError {
    /// The embedded font could not be registered.
    #[error("the embedded font (DejaVu Sans) could not be loaded")]
    Font,
    /// The plotting library failed (writing the file included).
    #[error("{path}: cannot draw the budget's picture: {problem}")]
    Draw {
        /// The picture file.
        path: String,
        /// The plotting library's message.
        problem: String,
    },
}

impl crate::outcome::Classify for PictureError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        // Drawing the picture: a failure of its own (exit 1).
        None
    }
}

/// One contributor: its name and per-coefficient 1σ (or bias), front and back.
struct Contributor {
    name: String,
    front: Vec<f64>,
    back: Vec<f64>,
}

fn contributors(budget: &Budget) -> Vec<Contributor> {
    let mut all: Vec<Contributor> = budget
        .dofs
        .iter()
        .map(|d| Contributor {
            name: d.dof.name().into(),
            front: d.front_contribution_nm(),
            back: d.back_contribution_nm(),
        })
        .chain(budget.others.iter().map(|o| Contributor {
            name: o.name.clone(),
            front: o.front_nm.clone(),
            back: o.back_nm.clone(),
        }))
        .collect();
    // Ranked by the largest variance the contributor puts into any one
    // term (j ≥ 4), so that the term a contributor dominates gets its colour.
    let weight = |c: &Contributor| -> f64 {
        c.front
            .iter()
            .skip(3)
            .chain(c.back.iter().skip(3))
            .map(|v| v * v)
            .fold(0.0, f64::max)
    };
    all.sort_by(|a, b| weight(b).total_cmp(&weight(a)));
    all
}

/// The segments of one term's bar: `(colour index or TOP for the rest,
/// height nm)`, from the bottom.
fn segments(all: &[Contributor], back: bool, k: usize, total: f64) -> Vec<(usize, f64)> {
    let v2 = |c: &Contributor| {
        let v = if back { &c.back } else { &c.front };
        v.get(k).map_or(0.0, |x| x * x)
    };
    let sum: f64 = all.iter().map(v2).sum();
    if sum <= 0.0 {
        return Vec::new();
    }
    let mut out: Vec<(usize, f64)> = all
        .iter()
        .take(TOP)
        .enumerate()
        .map(|(i, c)| (i, total * v2(c) / sum))
        .collect();
    out.push((TOP, total * all.iter().skip(TOP).map(v2).sum::<f64>() / sum));
    out
}

/// Draws the picture to `path` (PNG), terms j = 4 … `last_j`.
///
/// # Errors
/// [`PictureError`] when the font or the drawing fails.
pub fn budget_png(budget: &Budget, path: &Path, last_j: usize) -> Result<(), PictureError> {
    register_font().map_err(|_| PictureError::Font)?;
    let fail = |e: &dyn std::fmt::Display| PictureError::Draw {
        path: path.display().to_string(),
        problem: e.to_string(),
    };
    let root = BitMapBackend::new(path, (1500, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| fail(&e))?;
    let (plots, legend) = root.split_horizontally(1230);
    let all = contributors(budget);
    let panels: Vec<bool> = if budget.back_fitted {
        vec![false, true]
    } else {
        vec![false]
    };
    let areas = plots.split_evenly((1, panels.len()));
    for (area, &back) in areas.iter().zip(&panels) {
        panel(budget, &all, area, back, last_j).map_err(|e| fail(&e))?;
    }
    draw_legend(&all, &legend).map_err(|e| fail(&e))?;
    root.present().map_err(|e| fail(&e))?;
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type Drawn<'a> = Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

fn panel<'a>(
    budget: &Budget,
    all: &[Contributor],
    area: &Area<'a>,
    back: bool,
    last_j: usize,
) -> Drawn<'a> {
    let total = total_std_nm(budget, back);
    let last = last_j.min(total.len()).max(4);
    let top = total
        .iter()
        .take(last)
        .skip(3)
        .copied()
        .fold(0.0, f64::max)
        .max(1e-9)
        * 1.08;
    let title = format!(
        "{} surface: 1σ per Zernike term",
        if back { "Back" } else { "Front" }
    );
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FAMILY, 24))
        .margin(14)
        .x_label_area_size(70)
        .y_label_area_size(80)
        .build_cartesian_2d(3.5f64..last as f64 + 0.5, 0.0..top)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(last - 3)
        .x_label_formatter(&|x| {
            let j = x.round() as usize;
            if (x - j as f64).abs() < 1e-6 {
                format!("Z{j}")
            } else {
                String::new()
            }
        })
        .y_label_formatter(&|y| {
            let s = format!("{y:.3}");
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        })
        .max_light_lines(0)
        .x_desc("Z4 defocus, Z5–6 astigmatism, Z7–8 coma, Z9–10 trefoil, Z11 spherical")
        .y_desc("1σ, nm")
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 15))
        .draw()?;
    for (k, &t) in total.iter().enumerate().take(last).skip(3) {
        let x = (k + 1) as f64;
        let mut y0 = 0.0;
        for (c, h) in segments(all, back, k, t) {
            let colour = if c < TOP { COLOURS[c] } else { REST };
            chart.draw_series(std::iter::once(Rectangle::new(
                [(x - 0.35, y0), (x + 0.35, y0 + h)],
                colour.filled(),
            )))?;
            y0 += h;
        }
    }
    Ok(())
}

fn draw_legend<'a>(all: &[Contributor], area: &Area<'a>) -> Drawn<'a> {
    let style = (FAMILY, 16).into_font().color(&BLACK);
    area.draw(&Text::new("largest contributors", (10, 60), style.clone()))?;
    let mut entries: Vec<(String, RGBColor)> = all
        .iter()
        .take(TOP)
        .enumerate()
        .map(|(i, c)| (c.name.clone(), COLOURS[i]))
        .collect();
    if all.len() > TOP {
        entries.push((format!("the other {}", all.len() - TOP), REST));
    }
    for (i, (name, colour)) in entries.iter().enumerate() {
        let y = 95 + 32 * i as i32;
        area.draw(&Rectangle::new([(10, y), (32, y + 20)], colour.filled()))?;
        area.draw(&Text::new(name.clone(), (40, y + 2), style.clone()))?;
    }
    let note = (FAMILY, 13).into_font().color(&RGBColor(90, 90, 90));
    let y = 110 + 32 * entries.len() as i32;
    for (i, line) in [
        "bar height: total 1σ;",
        "split: shares of the",
        "variance (correlations",
        "ignored in the split)",
    ]
    .iter()
    .enumerate()
    {
        area.draw(&Text::new(*line, (10, y + 18 * i as i32), note.clone()))?;
    }
    Ok(())
}
