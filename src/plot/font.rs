//! Text in pictures: DejaVu Sans, embedded in the binary and registered
//! with `plotters` as "sans-serif" (so no system font is looked up), the
//! sizes used, and how numbers are written on axes.

use std::sync::OnceLock;

use plotters::style::{register_font, FontStyle, IntoFont, TextStyle, BLACK};

use super::PlotError;

/// DejaVu Sans (Bitstream Vera licence, `assets/fonts/LICENSE`).
static DEJAVU_SANS: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// The family every text style names.
pub(crate) const FAMILY: &str = "sans-serif";
/// Picture titles, in pixels.
pub(super) const TITLE_PX: f64 = 22.0;
/// Axis names and legends.
pub(super) const LABEL_PX: f64 = 18.0;
/// Tick labels.
pub(super) const TICK_PX: f64 = 16.0;

/// Registers the embedded font once per process.
///
/// # Errors
/// [`PlotError::Font`] if the font data cannot be parsed.
pub(crate) fn register() -> Result<(), PlotError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| register_font(FAMILY, FontStyle::Normal, DEJAVU_SANS).is_ok());
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// Black text of `px` pixels.
pub(super) fn text(px: f64) -> TextStyle<'static> {
    (FAMILY, px).into_font().color(&BLACK)
}

/// The width of `text` at `px` pixels, or 0 if the font is not registered.
pub(super) fn text_width(text: &str, px: f64) -> u32 {
    (FAMILY, px)
        .into_font()
        .box_size(text)
        .map_or(0, |(w, _)| w)
}

/// A linear-axis tick label: the shortest decimal (at most six places)
/// that shows `v`, so "0.2", "20", "-1.5"; scientific beyond 10⁶ or below
/// 10⁻⁴; never "-0".
pub(super) fn tick_label(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v.is_nan() {
            String::new()
        } else {
            "0".into()
        };
    }
    let a = v.abs();
    if !(1e-4..1e6).contains(&a) {
        return format!("{v:e}");
    }
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.to_string()
    }
}

/// A log-axis tick label: powers of ten from 0.001 to 1000 as decimals,
/// others as 10 with a superscript exponent ("10⁻⁶", "10⁵"); values
/// between powers of ten get a label only when `all` (an axis spanning
/// less than a decade), else none (a bare tick).
pub(super) fn log_tick_label(v: f64, all: bool) -> String {
    let e = v.log10().round();
    let power = v > 0.0 && (v.log10() - e).abs() < 1e-9;
    if !power {
        return if all { tick_label(v) } else { String::new() };
    }
    if (-3.0..=3.0).contains(&e) {
        return tick_label(10f64.powi(e as i32));
    }
    let digits: String = (e as i32)
        .to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            d => ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'][d as usize - '0' as usize],
        })
        .collect();
    format!("10{digits}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_embedded_font_registers() {
        register().unwrap();
        register().unwrap();
    }

    #[test]
    fn linear_labels_are_short_decimals() {
        let got: Vec<String> = [0.0, -0.0, 0.2, 0.30000000000000004, 20.0, -60.0, 1.5e-3]
            .iter()
            .map(|&v| tick_label(v))
            .collect();
        assert_eq!(got, ["0", "0", "0.2", "0.3", "20", "-60", "0.0015"]);
        assert_eq!(tick_label(5e-6), "5e-6");
        assert_eq!(tick_label(2e7), "2e7");
    }

    #[test]
    fn log_labels_write_powers_of_ten() {
        let got: Vec<String> = [1e-6, 1e-3, 0.1, 1.0, 10.0, 1000.0, 1e4]
            .iter()
            .map(|&v| log_tick_label(v, false))
            .collect();
        assert_eq!(got, ["10⁻⁶", "0.001", "0.1", "1", "10", "1000", "10⁴"]);
        assert_eq!(log_tick_label(3.0, false), "");
        assert_eq!(log_tick_label(3.0, true), "3");
    }
}
