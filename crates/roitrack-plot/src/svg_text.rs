//! Text drawn as outlines in the SVG files: the SVG backend writes `<text font-family="roitrack-sans">`, which a
//! viewer draws with whatever font it has under that name (none: a fallback font, other widths, labels that overlap).
//! Each `<text>` is drawn as a `<path>` of the embedded font's glyph outlines, laid out with its advances and
//! kerning, so an SVG looks like its PNG in every viewer and needs no font at all; the `<text>` stays, made
//! transparent, so that the words can still be searched and selected.

use ab_glyph::{Font, FontRef, GlyphId, OutlineCurve, Point};

/// The x-height of the embedded font (DejaVu Sans: 1120 of 2048 units per em), for the SVG backend's `ex` offsets.
const X_HEIGHT_EM: f32 = 1120.0 / 2048.0;

/// `svg` with every `<text ...>content</text>` element replaced by a `<path>` of the content's glyph outlines.
pub(crate) fn outline_text(svg: &str, font: &[u8]) -> Result<String, String> {
    let font = FontRef::try_from_slice(font).map_err(|e| e.to_string())?;
    let mut out = String::with_capacity(svg.len());
    let mut rest = svg;
    while let Some(start) = rest.find("<text") {
        out.push_str(&rest[..start]);
        let element = &rest[start..];
        let Some(open_end) = element.find('>') else {
            return Err("an unterminated <text> tag".to_string());
        };
        let Some(close) = element.find("</text>") else {
            return Err("a <text> element without </text>".to_string());
        };
        let attributes = parse_attributes(&element[5..open_end]);
        let content = unescape(element[open_end + 1..close].trim());
        out.push_str(&text_path(&font, &attributes, &content));
        // The text itself stays, invisible, for search, selection and screen readers.
        let tag = &element[..open_end];
        let hidden = match tag.find("opacity=\"") {
            Some(at) => {
                let value_end = tag[at + 9..].find('"').map_or(tag.len(), |e| at + 9 + e);
                format!("{}opacity=\"0{}", &tag[..at], &tag[value_end..])
            }
            None => format!("{tag} opacity=\"0\""),
        };
        out.push_str(&hidden);
        out.push_str(&element[open_end..close + "</text>".len()]);
        rest = &element[close + "</text>".len()..];
    }
    out.push_str(rest);
    Ok(out)
}

fn parse_attributes(text: &str) -> Vec<(String, String)> {
    let mut attributes = Vec::new();
    let mut rest = text.trim_start();
    while let Some(eq) = rest.find("=\"") {
        let name = rest[..eq].trim().to_string();
        let after = &rest[eq + 2..];
        let Some(end) = after.find('"') else { break };
        attributes.push((name, after[..end].to_string()));
        rest = after[end + 1..].trim_start();
    }
    attributes
}

fn unescape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        let tail = &rest[amp..];
        let Some(semi) = tail.find(';') else {
            out.push_str(tail);
            return out;
        };
        let entity = &tail[1..semi];
        let decoded = match entity {
            "amp" => Some('&'),
            "lt" => Some('<'),
            "gt" => Some('>'),
            "quot" => Some('"'),
            "apos" => Some('\''),
            _ => entity
                .strip_prefix("#x")
                .and_then(|hex| u32::from_str_radix(hex, 16).ok())
                .or_else(|| entity.strip_prefix('#').and_then(|dec| dec.parse().ok()))
                .and_then(char::from_u32),
        };
        match decoded {
            Some(c) => {
                out.push(c);
                rest = &tail[semi + 1..];
            }
            None => {
                out.push('&');
                rest = &tail[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

/// The vertical offset of an SVG length in `em` or `ex` (the backend's `dy`), in px for `size_px`.
fn offset_px(length: &str, size_px: f32) -> f32 {
    if let Some(em) = length.strip_suffix("em") {
        em.parse::<f32>().unwrap_or(0.0) * size_px
    } else if let Some(ex) = length.strip_suffix("ex") {
        ex.parse::<f32>().unwrap_or(0.0) * X_HEIGHT_EM * size_px
    } else {
        length.trim_end_matches("px").parse::<f32>().unwrap_or(0.0)
    }
}

fn text_path(font: &FontRef, attributes: &[(String, String)], content: &str) -> String {
    let get = |name: &str| {
        attributes
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    };
    let number = |name: &str| get(name).and_then(|v| v.parse::<f32>().ok()).unwrap_or(0.0);
    let size_px = number("font-size");
    let units_per_em = font.units_per_em().unwrap_or(2048.0);
    let scale = size_px / units_per_em;
    let glyphs: Vec<GlyphId> = content.chars().map(|c| font.glyph_id(c)).collect();
    let mut pen = Vec::with_capacity(glyphs.len());
    let mut advance = 0.0f32;
    for (k, &id) in glyphs.iter().enumerate() {
        if k > 0 {
            advance += font.kern_unscaled(glyphs[k - 1], id);
        }
        pen.push(advance);
        advance += font.h_advance_unscaled(id);
    }
    let width = advance * scale;
    let x = number("x")
        - match get("text-anchor") {
            Some("middle") => 0.5 * width,
            Some("end") => width,
            _ => 0.0,
        };
    let baseline = number("y") + get("dy").map_or(0.0, |dy| offset_px(dy, size_px));
    let mut d = String::new();
    for (&id, &origin) in glyphs.iter().zip(&pen) {
        let Some(outline) = font.outline(id) else {
            continue;
        };
        let at = |p: Point| (x + (origin + p.x) * scale, baseline - p.y * scale);
        let mut current: Option<Point> = None;
        for curve in &outline.curves {
            let (first, last) = match curve {
                OutlineCurve::Line(a, b) => (*a, *b),
                OutlineCurve::Quad(a, _, c) => (*a, *c),
                OutlineCurve::Cubic(a, _, _, d) => (*a, *d),
            };
            if current != Some(first) {
                if current.is_some() {
                    d.push('Z');
                }
                let (px, py) = at(first);
                d.push_str(&format!("M{px:.2} {py:.2}"));
            }
            match curve {
                OutlineCurve::Line(_, b) => {
                    let (bx, by) = at(*b);
                    d.push_str(&format!("L{bx:.2} {by:.2}"));
                }
                OutlineCurve::Quad(_, b, c) => {
                    let ((bx, by), (cx, cy)) = (at(*b), at(*c));
                    d.push_str(&format!("Q{bx:.2} {by:.2} {cx:.2} {cy:.2}"));
                }
                OutlineCurve::Cubic(_, b, c, e) => {
                    let ((bx, by), (cx, cy), (ex, ey)) = (at(*b), at(*c), at(*e));
                    d.push_str(&format!("C{bx:.2} {by:.2} {cx:.2} {cy:.2} {ex:.2} {ey:.2}"));
                }
            }
            current = Some(last);
        }
        if current.is_some() {
            d.push('Z');
        }
    }
    if d.is_empty() {
        return String::new();
    }
    let mut path = format!("<path d=\"{d}\"");
    for name in ["fill", "opacity", "transform"] {
        if let Some(value) = get(name) {
            path.push_str(&format!(" {name}=\"{value}\""));
        }
    }
    path.push_str("/>");
    path
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_becomes_paths_placed_by_its_anchor() {
        let font = crate::FONT_BYTES;
        let svg = "<svg><text x=\"100\" y=\"50\" dy=\"0.76em\" text-anchor=\"middle\" font-family=\"roitrack-sans\" \
                   font-size=\"20\" opacity=\"1\" fill=\"#000000\" transform=\"rotate(270, 100, 50)\">\nA &amp; B\n</text>\
                   <line x1=\"0\"/></svg>";
        let out = outline_text(svg, font).unwrap();
        assert!(out.contains("<path d=\"M") && out.contains("<line x1=\"0\"/>"));
        // The words stay, transparent.
        assert!(out.contains("opacity=\"0\" fill=\"#000000\"") && out.contains("A &amp; B"));
        assert!(
            out.contains("transform=\"rotate(270, 100, 50)\"") && out.contains("fill=\"#000000\"")
        );
        // Centred on x = 100: the outline's x extent is symmetric about it (the path's coordinates come in x, y pairs).
        let d = &out[out.find("d=\"").unwrap() + 3..];
        let d = &d[..d.find('"').unwrap()];
        let numbers: Vec<f32> = d
            .split(|c: char| c.is_ascii_alphabetic() || c == ' ')
            .filter_map(|s| s.parse().ok())
            .collect();
        let xs: Vec<f32> = numbers.iter().step_by(2).copied().collect();
        let ys: Vec<f32> = numbers.iter().skip(1).step_by(2).copied().collect();
        let (lo, hi) = xs
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(((lo + hi) / 2.0 - 100.0).abs() < 1.5, "{lo} {hi}");
        // Top-anchored (dy 0.76em): capitals stand between y = 50 and the baseline 0.76 em below.
        let (top, bottom) = ys
            .iter()
            .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
        assert!(
            top > 49.0 && (bottom - (50.0 + 0.76 * 20.0)).abs() < 0.5,
            "{top} {bottom}"
        );
        assert_eq!(
            unescape("a &lt;b&gt; &#65;&#x42; &unknown; &"),
            "a <b> AB &unknown; &"
        );
    }
}
