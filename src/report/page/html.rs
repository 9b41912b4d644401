//! The report page as text: a self-contained HTML document (inline CSS,
//! images as `data:` URLs of base64 PNG), with no script, font or picture
//! fetched from anywhere, so it opens the same on a machine without a
//! network and can be filed as one file.

use base64::Engine as _;

/// Escapes `&`, `<`, `>` and `"` for text and attribute values.
pub fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            _ => out.push(c),
        }
    }
    out
}

/// The page's style: one column, tables with thin rules, pictures scaled to
/// the column and printed without a page break inside.
const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;\
color:#222}h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #999;margin-top:1.6em}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:2px 8px;\
text-align:right}th{background:#eee}td.l,th.l{text-align:left}figure{margin:.8em 0;\
break-inside:avoid}figure img{max-width:100%}figcaption{font-size:.9em;color:#555}\
.warn{background:#fff3cd;border:1px solid #e0c060;padding:.4em .8em;margin:.3em 0}\
.ok{color:#2a6e2a}.note{color:#555;font-size:.9em}";

/// A page being assembled: sections in the order they are added.
#[derive(Debug, Default)]
pub struct Page {
    title: String,
    body: String,
}

impl Page {
    /// An empty page titled `title`.
    pub fn new(title: &str) -> Page {
        Page {
            title: title.to_string(),
            body: format!("<h1>{}</h1>\n", escape(title)),
        }
    }

    /// A section heading.
    pub fn heading(&mut self, text: &str) {
        self.body.push_str(&format!("<h2>{}</h2>\n", escape(text)));
    }

    /// A paragraph of text.
    pub fn paragraph(&mut self, text: &str) {
        self.body.push_str(&format!("<p>{}</p>\n", escape(text)));
    }

    /// A note in smaller print.
    pub fn note(&mut self, text: &str) {
        self.body
            .push_str(&format!("<p class=\"note\">{}</p>\n", escape(text)));
    }

    /// A warning box.
    pub fn warning(&mut self, text: &str) {
        self.body
            .push_str(&format!("<div class=\"warn\">⚠ {}</div>\n", escape(text)));
    }

    /// A line saying that nothing needed a warning.
    pub fn fine(&mut self, text: &str) {
        self.body
            .push_str(&format!("<p class=\"ok\">✓ {}</p>\n", escape(text)));
    }

    /// A table: the first column left-aligned (names), the others right.
    pub fn table(&mut self, header: &[&str], rows: &[Vec<String>]) {
        let mut t = String::from("<table>\n<tr>");
        for (i, h) in header.iter().enumerate() {
            let class = if i == 0 { " class=\"l\"" } else { "" };
            t.push_str(&format!("<th{class}>{}</th>", escape(h)));
        }
        t.push_str("</tr>\n");
        for row in rows {
            t.push_str("<tr>");
            for (i, cell) in row.iter().enumerate() {
                let class = if i == 0 { " class=\"l\"" } else { "" };
                t.push_str(&format!("<td{class}>{}</td>", escape(cell)));
            }
            t.push_str("</tr>\n");
        }
        t.push_str("</table>\n");
        self.body.push_str(&t);
    }

    /// A table of names and values, both left-aligned, without a header.
    pub fn pairs(&mut self, rows: &[Vec<String>]) {
        let mut t = String::from("<table>\n");
        for row in rows {
            t.push_str("<tr>");
            for (i, cell) in row.iter().enumerate() {
                let tag = if i == 0 { "th" } else { "td" };
                t.push_str(&format!("<{tag} class=\"l\">{}</{tag}>", escape(cell)));
            }
            t.push_str("</tr>\n");
        }
        t.push_str("</table>\n");
        self.body.push_str(&t);
    }

    /// A picture inlined as a base64 PNG, with its caption.
    pub fn png(&mut self, png: &[u8], caption: &str) {
        let data = base64::engine::general_purpose::STANDARD.encode(png);
        self.body.push_str(&format!(
            "<figure><img alt=\"{}\" src=\"data:image/png;base64,{data}\">\
             <figcaption>{}</figcaption></figure>\n",
            escape(caption),
            escape(caption)
        ));
    }

    /// The whole document.
    pub fn finish(self) -> String {
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
             <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n{}</body>\n</html>\n",
            escape(&self.title),
            self.body
        )
    }
}

/// `seconds` since the Unix epoch as `YYYY-MM-DD hh:mm:ss UTC` (the civil
/// calendar from the day count, proleptic Gregorian; Howard Hinnant's
/// `civil_from_days`: no date crate is among the dependencies and this is
/// the one date the report prints).
pub fn utc_date(seconds: u64) -> String {
    let days = (seconds / 86_400) as i64;
    let secs = seconds % 86_400;
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02} {:02}:{:02}:{:02} UTC",
        secs / 3600,
        (secs / 60) % 60,
        secs % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_match_known_epochs() {
        // Reference values: `date -u -d @N` (GNU coreutils).
        assert_eq!(utc_date(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc_date(951_782_400), "2000-02-29 00:00:00 UTC");
        assert_eq!(utc_date(1_798_761_599), "2026-12-31 23:59:59 UTC");
    }

    #[test]
    fn text_is_escaped() {
        let mut p = Page::new("a<b");
        p.paragraph("x & \"y\"");
        let html = p.finish();
        assert!(html.contains("a&lt;b") && html.contains("x &amp; &quot;y&quot;"));
        assert!(!html.contains("a<b"));
    }
}
