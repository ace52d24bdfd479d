//! The readers of JSON values the problem and suite files share: each refusal names the field as a path from the
//! file's top (`instances[0].pixels[3]`).

use serde_json::{Map, Value};

use super::PnpError;

/// `parent.key`, or `key` at the top.
pub(super) fn join(parent: &str, key: &str) -> String {
    if parent.is_empty() {
        key.to_owned()
    } else {
        format!("{parent}.{key}")
    }
}

/// What a JSON value is, for "expected X, got Y".
fn kind(value: &Value) -> String {
    match value {
        Value::Null => "null".to_owned(),
        Value::Bool(b) => b.to_string(),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) if s.chars().count() <= 40 => format!("the string {s:?}"),
        Value::String(_) => "a string".to_owned(),
        Value::Array(a) => format!("an array of {}", a.len()),
        Value::Object(_) => "an object".to_owned(),
    }
}

pub(super) fn expected(path: &str, what: &str, value: &Value) -> PnpError {
    let at = if path.is_empty() { "the file" } else { path };
    PnpError::new(format!("{at}: expected {what}, got {}", kind(value)))
}

pub(super) fn object<'a>(value: &'a Value, path: &str) -> Result<&'a Map<String, Value>, PnpError> {
    value
        .as_object()
        .ok_or_else(|| expected(path, "an object", value))
}

/// The field `key` of `object` (at `path`), which must be there (null counts as missing).
pub(super) fn field<'a>(
    object: &'a Map<String, Value>,
    path: &str,
    key: &str,
) -> Result<&'a Value, PnpError> {
    match object.get(key) {
        Some(Value::Null) | None => Err(PnpError::new(format!("{} is missing", join(path, key)))),
        Some(value) => Ok(value),
    }
}

pub(super) fn array<'a>(value: &'a Value, path: &str) -> Result<&'a [Value], PnpError> {
    value
        .as_array()
        .map(Vec::as_slice)
        .ok_or_else(|| expected(path, "an array", value))
}

pub(super) fn number(value: &Value, path: &str) -> Result<f64, PnpError> {
    value
        .as_f64()
        .ok_or_else(|| expected(path, "a number", value))
}

/// A fixed-length array of numbers (a pixel, a point, a matrix row).
pub(super) fn numbers<const N: usize>(value: &Value, path: &str) -> Result<[f64; N], PnpError> {
    let items = array(value, path)?;
    if items.len() != N {
        return Err(expected(path, &format!("an array of {N} numbers"), value));
    }
    let mut out = [0.0; N];
    for (k, (slot, item)) in out.iter_mut().zip(items).enumerate() {
        *slot = number(item, &format!("{path}[{k}]"))?;
    }
    Ok(out)
}
