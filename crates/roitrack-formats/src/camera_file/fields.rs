//! The YAML every camera-file reader goes through: the first document, parsed with its depth checked, and the
//! numbers, lists and image sizes read from it, with errors that name the file and the field.

use std::path::Path;

use serde_yaml_ng::{Mapping, Value};

use crate::FormatError;
use crate::limits::check_yaml_depth;

/// The text up to the end of its first YAML document (a `---` or `...` line after some content), so that a topic
/// echo's trailing separators and later messages are left out. Line numbers are unchanged.
pub(super) fn first_document(text: &str) -> &str {
    let mut offset = 0;
    let mut seen_content = false;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_end();
        if (trimmed == "---" || trimmed == "...") && seen_content {
            return &text[..offset];
        }
        if !trimmed.is_empty()
            && !trimmed.starts_with('#')
            && !trimmed.starts_with('%')
            && trimmed != "---"
        {
            seen_content = true;
        }
        offset += line.len();
    }
    text
}

/// The first YAML document of `text` as a value; syntax errors name the line. Nesting is checked first: the parser's
/// time grows with the square of the depth.
pub(super) fn yaml_value(text: &str, path: &Path) -> Result<Value, FormatError> {
    let text = first_document(text);
    check_yaml_depth(text, path)?;
    serde_yaml_ng::from_str::<Value>(text).map_err(|e| {
        let line = e.location().map(|l| l.line() as u64);
        FormatError::new(path, format!("not valid YAML: {e}")).with_line(line)
    })
}

/// `path`'s stem, the name of a camera from a file that has none.
pub(super) fn file_stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

pub(super) fn field_error(path: &Path, field: &str, message: impl Into<String>) -> FormatError {
    FormatError::new(path, message).with_field(field)
}

/// The value at `key` of `map`.
pub(super) fn get<'a>(map: &'a Mapping, key: &str) -> Option<&'a Value> {
    map.get(key)
}

/// A number (YAML integer or float).
pub(super) fn number(value: &Value, path: &Path, field: &str) -> Result<f64, FormatError> {
    match value {
        Value::Number(n) => n
            .as_f64()
            .ok_or_else(|| field_error(path, field, "not a number")),
        other => Err(field_error(
            path,
            field,
            format!("expected a number, got {}", describe(other)),
        )),
    }
}

pub(super) fn describe(value: &Value) -> String {
    match value {
        Value::Null => "nothing".to_string(),
        Value::Bool(b) => format!("{b}"),
        Value::Number(n) => format!("{n}"),
        Value::String(s) => format!("{s:?}"),
        Value::Sequence(s) => format!("a list of {}", s.len()),
        Value::Mapping(_) => "a mapping".to_string(),
        Value::Tagged(_) => "a tagged value".to_string(),
    }
}

/// A list of finite numbers.
pub(super) fn numbers(value: &Value, path: &Path, field: &str) -> Result<Vec<f64>, FormatError> {
    let Value::Sequence(items) = value else {
        return Err(field_error(
            path,
            field,
            format!("expected a list of numbers, got {}", describe(value)),
        ));
    };
    items
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let f = format!("{field}[{i}]");
            let x = number(v, path, &f)?;
            if x.is_finite() {
                Ok(x)
            } else {
                Err(field_error(
                    path,
                    &f,
                    format!("must be a finite number, got {x}"),
                ))
            }
        })
        .collect()
}

/// A positive image size.
fn size(value: &Value, path: &Path, field: &str) -> Result<u32, FormatError> {
    match value.as_u64().and_then(|v| u32::try_from(v).ok()) {
        Some(v) if v > 0 => Ok(v),
        _ => Err(field_error(
            path,
            field,
            format!(
                "expected a positive image size in pixels, got {}",
                describe(value)
            ),
        )),
    }
}

/// The image width and height at `keys` of `map`, each optional ([`size`]), named `fields` in errors; the width
/// is read first.
pub(super) fn width_height(
    map: &Mapping,
    keys: [&str; 2],
    path: &Path,
    fields: [&str; 2],
) -> Result<(Option<u32>, Option<u32>), FormatError> {
    let width = get(map, keys[0])
        .map(|v| size(v, path, fields[0]))
        .transpose()?;
    let height = get(map, keys[1])
        .map(|v| size(v, path, fields[1]))
        .transpose()?;
    Ok((width, height))
}

/// `[width, height]` as an image size: two whole numbers of pixels from 1 to `u32::MAX`; else `None`.
pub(super) fn image_size_px(wh: &[f64]) -> Option<(u32, u32)> {
    match *wh {
        [w, h]
            if w >= 1.0
                && h >= 1.0
                && w.fract() == 0.0
                && h.fract() == 0.0
                && w <= u32::MAX as f64
                && h <= u32::MAX as f64 =>
        {
            Some((w as u32, h as u32))
        }
        _ => None,
    }
}
