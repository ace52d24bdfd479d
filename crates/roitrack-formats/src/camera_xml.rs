//! OpenCV FileStorage XML, read into the same shape as its YAML form, so that one reader serves both.
//!
//! FileStorage XML is a small subset of XML: an `<?xml ...?>` declaration, a root `<opencv_storage>`, and elements
//! holding either other elements (a mapping; `<_>` items make a list) or text (a number, a `"quoted"` or plain
//! string, or numbers separated by white space, as in a matrix's `<data>`). Attributes (`type_id="opencv-matrix"`)
//! say nothing the content does not, and are skipped. This reader takes exactly that subset and refuses the rest
//! with the line where it stops.

use serde_yaml_ng::{Mapping, Number, Value};

/// Nesting deeper than this is refused (FileStorage files are two or three levels deep).
const MAX_DEPTH: usize = 32;

/// The FileStorage XML `text` as a YAML value: the root's elements as a mapping. Errors: (line, message).
pub(crate) fn opencv_xml_to_value(text: &str) -> Result<Value, (Option<u64>, String)> {
    let mut p = Parser {
        text: text.trim_start_matches('\u{feff}'),
        pos: 0,
    };
    p.skip_misc()?;
    let (name, self_closing) = p.open_tag()?;
    if name != "opencv_storage" {
        return Err(p.error(format!(
            "the root element is <{name}>: an OpenCV FileStorage XML file has <opencv_storage>"
        )));
    }
    let value = if self_closing {
        Value::Mapping(Mapping::new())
    } else {
        p.content(&name, 1)?
    };
    p.skip_misc()?;
    if p.pos < p.text.len() {
        return Err(p.error("unexpected content after </opencv_storage>".to_string()));
    }
    Ok(value)
}

struct Parser<'a> {
    text: &'a str,
    pos: usize,
}

impl Parser<'_> {
    fn rest(&self) -> &str {
        &self.text[self.pos..]
    }

    fn line(&self) -> u64 {
        1 + self.text[..self.pos]
            .bytes()
            .filter(|&b| b == b'\n')
            .count() as u64
    }

    fn error(&self, message: String) -> (Option<u64>, String) {
        (Some(self.line()), message)
    }

    fn skip_whitespace(&mut self) {
        let rest = self.rest();
        self.pos += rest.len() - rest.trim_start().len();
    }

    /// Skips white space, the declaration, comments and a doctype.
    fn skip_misc(&mut self) -> Result<(), (Option<u64>, String)> {
        loop {
            self.skip_whitespace();
            let (open, close) = if self.rest().starts_with("<?") {
                ("<?", "?>")
            } else if self.rest().starts_with("<!--") {
                ("<!--", "-->")
            } else if self.rest().starts_with("<!") {
                ("<!", ">")
            } else {
                return Ok(());
            };
            match self.rest()[open.len()..].find(close) {
                Some(end) => self.pos += open.len() + end + close.len(),
                None => return Err(self.error(format!("unterminated {open}"))),
            }
        }
    }

    /// `<name attrs>` or `<name attrs/>` at the current position: the name, and whether the element is empty.
    fn open_tag(&mut self) -> Result<(String, bool), (Option<u64>, String)> {
        if !self.rest().starts_with('<') {
            return Err(self.error("expected an element <...>".to_string()));
        }
        let Some(end) = self.rest().find('>') else {
            return Err(self.error("unterminated tag".to_string()));
        };
        let inner = &self.rest()[1..end];
        let self_closing = inner.ends_with('/');
        let inner = inner.trim_end_matches('/');
        let name: String = inner.chars().take_while(|c| !c.is_whitespace()).collect();
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_alphanumeric() || matches!(c, '_' | '-' | '.' | ':'))
        {
            return Err(self.error(format!("not an element name: {name:?}")));
        }
        self.pos += end + 1;
        Ok((name, self_closing))
    }

    /// The content of element `name` up to and including its closing tag.
    fn content(&mut self, name: &str, depth: usize) -> Result<Value, (Option<u64>, String)> {
        if depth > MAX_DEPTH {
            return Err(self.error(format!("elements nested deeper than {MAX_DEPTH}")));
        }
        let mut text = String::new();
        let mut children: Vec<(String, Value)> = Vec::new();
        loop {
            let Some(lt) = self.rest().find('<') else {
                return Err(self.error(format!("<{name}> is not closed")));
            };
            text.push_str(&decode_entities(&self.rest()[..lt]).map_err(|e| self.error(e))?);
            self.pos += lt;
            if self.rest().starts_with("<!--") {
                match self.rest().find("-->") {
                    Some(end) => self.pos += end + 3,
                    None => return Err(self.error("unterminated comment".to_string())),
                }
                continue;
            }
            if let Some(after) = self.rest().strip_prefix("</") {
                let Some(end) = after.find('>') else {
                    return Err(self.error("unterminated closing tag".to_string()));
                };
                let closing = after[..end].trim();
                if closing != name {
                    return Err(self.error(format!("</{closing}> closes <{name}>")));
                }
                self.pos += 2 + end + 1;
                break;
            }
            let line = self.line();
            let (child, self_closing) = self.open_tag()?;
            let value = if self_closing {
                Value::Null
            } else {
                self.content(&child, depth + 1)?
            };
            if child != "_" && children.iter().any(|(k, _)| *k == child) {
                return Err((Some(line), format!("<{child}> given twice in <{name}>")));
            }
            children.push((child, value));
        }
        if children.is_empty() {
            return Ok(scalar(text.trim(), name == "data"));
        }
        if !text.trim().is_empty() {
            return Err(self.error(format!("<{name}> mixes text and elements")));
        }
        if children.iter().all(|(k, _)| k == "_") {
            return Ok(Value::Sequence(
                children.into_iter().map(|(_, v)| v).collect(),
            ));
        }
        let mut map = Mapping::new();
        for (k, v) in children {
            map.insert(Value::String(k), v);
        }
        Ok(Value::Mapping(map))
    }
}

/// An element's text: a number, numbers separated by white space (always a list for `<data>`), or a string.
fn scalar(text: &str, is_data: bool) -> Value {
    if let Some(quoted) = text.strip_prefix('"').and_then(|t| t.strip_suffix('"')) {
        return Value::String(quoted.to_string());
    }
    let tokens: Vec<&str> = text.split_whitespace().collect();
    let parsed: Option<Vec<Value>> = tokens.iter().map(|t| number(t)).collect();
    match parsed {
        Some(mut values) if !values.is_empty() => {
            if values.len() == 1 && !is_data {
                values.remove(0)
            } else {
                Value::Sequence(values)
            }
        }
        Some(_) if is_data => Value::Sequence(Vec::new()),
        _ if text.is_empty() => Value::Null,
        _ => Value::String(text.to_string()),
    }
}

/// A number as OpenCV writes it: an integer, or a float such as `0.`, `1.5e-03`, `.Nan`, `.Inf`, `-.Inf`.
fn number(token: &str) -> Option<Value> {
    if let Ok(i) = token.parse::<i64>() {
        return Some(Value::Number(Number::from(i)));
    }
    let f = match token {
        ".Nan" | ".nan" | ".NaN" => f64::NAN,
        ".Inf" | ".inf" | "+.Inf" => f64::INFINITY,
        "-.Inf" | "-.inf" => f64::NEG_INFINITY,
        // Rust's parser also takes "inf" and "nan", which OpenCV never writes: leave them as text.
        t if t
            .bytes()
            .any(|b| b.is_ascii_alphabetic() && !matches!(b, b'e' | b'E')) =>
        {
            return None;
        }
        t => t.parse::<f64>().ok()?,
    };
    Some(Value::Number(Number::from(f)))
}

/// The text with XML's five entities and numeric character references replaced.
fn decode_entities(text: &str) -> Result<String, String> {
    if !text.contains('&') {
        return Ok(text.to_string());
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find('&') {
        out.push_str(&rest[..at]);
        let Some(end) = rest[at..].find(';') else {
            return Err("an & without its ;".to_string());
        };
        let entity = &rest[at + 1..at + end];
        let c = match entity {
            "lt" => '<',
            "gt" => '>',
            "amp" => '&',
            "quot" => '"',
            "apos" => '\'',
            e => {
                let code = if let Some(hex) = e.strip_prefix("#x") {
                    u32::from_str_radix(hex, 16).ok()
                } else {
                    e.strip_prefix('#').and_then(|d| d.parse::<u32>().ok())
                };
                code.and_then(char::from_u32)
                    .ok_or_else(|| format!("unknown entity &{e};"))?
            }
        };
        out.push(c);
        rest = &rest[at + end + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filestorage_subset() {
        let v = opencv_xml_to_value(
            "<?xml version=\"1.0\"?>\n<!-- c -->\n<opencv_storage>\n<w>640</w>\n<name>\"a &amp; b\"</name>\n\
             <K type_id=\"opencv-matrix\"><rows>1</rows><data>\n 1. 2.5e+00\n -3</data></K>\n<s>1 2</s>\
             <l><_>1</_><_>x</_></l><e/></opencv_storage>\n",
        )
        .unwrap();
        assert_eq!(v["w"].as_u64(), Some(640));
        assert_eq!(v["name"].as_str(), Some("a & b"));
        assert_eq!(
            v["K"]["data"],
            Value::Sequence(vec![1.0.into(), 2.5.into(), Value::from(-3)])
        );
        assert_eq!(v["s"].as_sequence().unwrap().len(), 2);
        assert_eq!(v["l"][1].as_str(), Some("x"));
        assert!(v["e"].is_null());
    }

    #[test]
    fn errors_name_the_line() {
        for (text, line, needle) in [
            (
                "<opencv_storage>\n<a>1</b>\n</opencv_storage>",
                2,
                "</b> closes <a>",
            ),
            ("<x/>", 1, "root element"),
            (
                "<opencv_storage>\n<a>1</a>\n<a>2</a>\n</opencv_storage>",
                3,
                "given twice",
            ),
            ("<opencv_storage>\n<a>1", 2, "not closed"),
            ("<opencv_storage></opencv_storage>\ntrailing", 2, "after"),
            (
                "<opencv_storage><a>&bogus;</a></opencv_storage>",
                1,
                "entity",
            ),
        ] {
            let (l, m) = opencv_xml_to_value(text).unwrap_err();
            assert_eq!(l, Some(line), "{text}: {m}");
            assert!(m.contains(needle), "{text}: {m}");
        }
        let deep = format!(
            "<opencv_storage>{}{}</opencv_storage>",
            "<a>".repeat(100),
            "</a>".repeat(100)
        );
        assert!(opencv_xml_to_value(&deep).unwrap_err().1.contains("deeper"));
    }
}
