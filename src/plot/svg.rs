//! Raster maps in SVG pictures: each is drawn first as a placeholder
//! rectangle (a fill whose opacity no picture uses otherwise), then that
//! `<rect>` is swapped for an `<image>` holding the map as a base64 PNG at
//! its own resolution, scaled without smoothing.

use plotters::style::RGBAColor;

use super::output::{encode_png, Raster};

/// The placeholder's fill. Its opacity, written as `opacity="0.012345"` by
/// the SVG backend, is what marks it.
pub(super) const PLACEHOLDER: RGBAColor = RGBAColor(255, 0, 255, PLACEHOLDER_OPACITY);
const PLACEHOLDER_OPACITY: f64 = 0.012345;

/// `svg` with its placeholder rectangles, in order, replaced by `rasters`.
/// Placeholders beyond the rasters' number (none in practice) stay.
pub(super) fn embed_rasters(svg: &str, rasters: &[Raster]) -> String {
    let marker = format!("opacity=\"{PLACEHOLDER_OPACITY}\"");
    let mut out = String::with_capacity(svg.len());
    let mut rest = svg;
    for raster in rasters {
        let Some(at) = rest.find(&marker) else {
            break;
        };
        let (Some(start), Some(len)) = (rest[..at].rfind("<rect"), rest[at..].find("/>")) else {
            break;
        };
        let tag = &rest[start..at + len + 2];
        out.push_str(&rest[..start]);
        out.push_str(&image_tag(tag, raster));
        rest = &rest[at + len + 2..];
    }
    out.push_str(rest);
    out
}

/// The `<image>` that takes the place of placeholder `rect`.
fn image_tag(rect: &str, raster: &Raster) -> String {
    let attr = |name: &str| {
        let key = format!(" {name}=\"");
        rect.find(&key)
            .and_then(|i| {
                let v = &rect[i + key.len()..];
                v.find('"').map(|j| v[..j].to_string())
            })
            .unwrap_or_else(|| "0".into())
    };
    let mut png = Vec::new();
    let size = (raster.width as u32, raster.height as u32);
    if encode_png(&mut png, size, &raster.rgb).is_err() {
        // Encoding into memory fails only for an inconsistent raster; keep
        // the placeholder rather than write a broken image.
        return rect.to_string();
    }
    format!(
        "<image x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\" preserveAspectRatio=\"none\" \
         style=\"image-rendering:pixelated\" href=\"data:image/png;base64,{}\"/>",
        attr("x"),
        attr("y"),
        attr("width"),
        attr("height"),
        base64(&png)
    )
}

/// Standard base64 (RFC 4648, with padding).
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc_4648_vectors() {
        // RFC 4648 §10.
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, coded) in cases {
            assert_eq!(base64(plain.as_bytes()), coded, "{plain}");
        }
    }

    #[test]
    fn placeholders_become_images_in_order() {
        let rect = |x: u32| {
            format!(
                "<rect x=\"{x}\" y=\"5\" width=\"40\" height=\"30\" \
                 opacity=\"{PLACEHOLDER_OPACITY}\" fill=\"#FF00FF\" stroke=\"none\"/>\n"
            )
        };
        let svg = format!("<svg>\n{}<line/>\n{}</svg>\n", rect(1), rect(2));
        let one = |v: u8| Raster {
            width: 1,
            height: 1,
            rgb: vec![v, v, v],
        };
        let out = embed_rasters(&svg, &[one(0), one(255)]);
        assert!(!out.contains("opacity=\"0.012345\""), "{out}");
        assert_eq!(out.matches("<image").count(), 2, "{out}");
        let first = out.find("<image x=\"1\" y=\"5\" width=\"40\" height=\"30\"");
        let second = out.find("<image x=\"2\"");
        assert!(first.is_some() && second > first, "{out}");
        assert!(out.contains("<line/>") && out.ends_with("</svg>\n"));
    }
}
