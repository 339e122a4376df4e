//! Reading JSON files value by value, so that every error names the file and the key.
//!
//! A [`JsonNode`] is a value together with its file and its JSON pointer (`/7/cam_K`); its
//! accessors check type and range and say which key failed and why. Writing goes through
//! [`bop_style_object`], which lays out a top-level map one entry a line, as the BOP toolkit
//! does, or [`write_pretty_json`] for Glint's own files.

use std::path::Path;

use glint_geometry::io::write_file_atomically;
use serde::Serialize;
use serde_json::Value;

use super::error::{DatasetError, read_file};

/// Reads and parses a JSON file.
pub(crate) fn read_json_file(path: &Path) -> Result<Value, DatasetError> {
    read_json_as(path)
}

/// Reads and deserialises a JSON file into `T`; syntax and type errors name the file, line
/// and column.
pub(crate) fn read_json_as<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T, DatasetError> {
    let bytes = read_file(path)?;
    serde_json::from_slice(&bytes).map_err(|error| DatasetError::Json {
        path: path.to_owned(),
        line: error.line(),
        column: error.column(),
        problem: error.to_string(),
    })
}

/// A JSON value, where it is (file and JSON pointer) and accessors whose errors say so.
#[derive(Clone, Debug)]
pub(crate) struct JsonNode<'a> {
    path: &'a Path,
    pointer: String,
    value: &'a Value,
}

impl<'a> JsonNode<'a> {
    /// The root value of the file at `path`.
    pub(crate) fn root(path: &'a Path, value: &'a Value) -> Self {
        Self {
            path,
            pointer: String::new(),
            value,
        }
    }

    /// An error about this value.
    pub(crate) fn error(&self, problem: impl Into<String>) -> DatasetError {
        DatasetError::Field {
            path: self.path.to_owned(),
            key: if self.pointer.is_empty() {
                "/ (the top level)".to_owned()
            } else {
                self.pointer.clone()
            },
            problem: problem.into(),
        }
    }

    fn child(&self, key: &str, value: &'a Value) -> Self {
        let escaped = key.replace('~', "~0").replace('/', "~1");
        Self {
            path: self.path,
            pointer: format!("{}/{escaped}", self.pointer),
            value,
        }
    }

    /// The entries of an object, in file order.
    pub(crate) fn entries(&self) -> Result<Vec<(&'a str, JsonNode<'a>)>, DatasetError> {
        let Value::Object(map) = self.value else {
            return Err(self.error(format!(
                "expected an object, found {}",
                describe(self.value)
            )));
        };
        Ok(map
            .iter()
            .map(|(key, value)| (key.as_str(), self.child(key, value)))
            .collect())
    }

    /// The items of an array.
    pub(crate) fn items(&self) -> Result<Vec<JsonNode<'a>>, DatasetError> {
        let Value::Array(items) = self.value else {
            return Err(self.error(format!("expected an array, found {}", describe(self.value))));
        };
        Ok(items
            .iter()
            .enumerate()
            .map(|(index, value)| self.child(&index.to_string(), value))
            .collect())
    }

    /// The member `name` of an object; an error if it is missing (or `null`).
    pub(crate) fn field(&self, name: &str) -> Result<JsonNode<'a>, DatasetError> {
        let Value::Object(map) = self.value else {
            return Err(self.error(format!(
                "expected an object with the key \"{name}\", found {}",
                describe(self.value)
            )));
        };
        match map.get(name) {
            Some(value) if !value.is_null() => Ok(self.child(name, value)),
            _ => Err(self.missing(name)),
        }
    }

    /// The error for the member `name` of this object being missing (or `null`).
    pub(crate) fn missing(&self, name: &str) -> DatasetError {
        self.child(name, &Value::Null).error("missing")
    }

    /// The member `name` of an object, `None` if this is not an object or it is missing or
    /// `null`.
    pub(crate) fn optional_field(&self, name: &str) -> Option<JsonNode<'a>> {
        match self.value.get(name) {
            Some(value) if !value.is_null() => Some(self.child(name, value)),
            _ => None,
        }
    }

    /// A finite number.
    pub(crate) fn f64(&self) -> Result<f64, DatasetError> {
        match self.value.as_f64() {
            Some(x) if x.is_finite() => Ok(x),
            _ => Err(self.error(format!("expected a number, found {}", describe(self.value)))),
        }
    }

    /// A string.
    pub(crate) fn str(&self) -> Result<&'a str, DatasetError> {
        self.value
            .as_str()
            .ok_or_else(|| self.error(format!("expected a string, found {}", describe(self.value))))
    }

    /// A whole number in `T`'s range; `3.0` counts as whole.
    pub(crate) fn integer<T: TryFrom<i64>>(&self) -> Result<T, DatasetError> {
        let whole = match self.value {
            Value::Number(n) => n.as_i64().or_else(|| {
                n.as_f64()
                    .filter(|x| x.fract() == 0.0 && x.abs() < 9.0e15)
                    .map(|x| x as i64)
            }),
            _ => None,
        };
        let Some(whole) = whole else {
            return Err(self.error(format!(
                "expected a whole number, found {}",
                describe(self.value)
            )));
        };
        T::try_from(whole).map_err(|_| {
            self.error(format!(
                "{whole} is out of range for a {}",
                std::any::type_name::<T>()
            ))
        })
    }

    /// An array of exactly `N` finite numbers.
    pub(crate) fn f64_array<const N: usize>(&self) -> Result<[f64; N], DatasetError> {
        let items = self.items()?;
        if items.len() != N {
            return Err(self.error(format!(
                "expected {N} numbers, found an array of {}",
                items.len()
            )));
        }
        let mut out = [0.0; N];
        for (slot, item) in out.iter_mut().zip(&items) {
            *slot = item.f64()?;
        }
        Ok(out)
    }

    /// An array of `N` numbers, or (for matrices) an array of rows holding `N` numbers in
    /// all: `[[a, b], [c, d]]` reads as `[a, b, c, d]`.
    pub(crate) fn f64_array_flattened<const N: usize>(&self) -> Result<[f64; N], DatasetError> {
        let items = self.items()?;
        if !items.iter().any(|item| item.value.is_array()) {
            return self.f64_array();
        }
        let mut flat = Vec::with_capacity(N);
        for row in &items {
            for entry in row.items()? {
                flat.push(entry.f64()?);
            }
        }
        flat.try_into().map_err(|flat: Vec<f64>| {
            self.error(format!(
                "expected {N} numbers (flat or in rows), found {}",
                flat.len()
            ))
        })
    }

    /// The value itself.
    pub(crate) fn value(&self) -> &'a Value {
        self.value
    }
}

/// A short description of a JSON value for error messages.
fn describe(value: &Value) -> String {
    match value {
        Value::Null => "null".to_owned(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) if s.len() <= 40 => format!("the string {s:?}"),
        Value::String(s) => format!("a string of {} bytes", s.len()),
        Value::Array(items) => format!("an array of {}", items.len()),
        Value::Object(map) => format!("an object with {} keys", map.len()),
    }
}

/// A top-level JSON object with one entry a line, keys in the iterator's order (the BOP
/// toolkit's layout: diff-friendly, compact, and valid JSON for every reader). `path` is the
/// file it is for, named in errors.
pub(crate) fn bop_style_object<K, V>(
    path: &Path,
    entries: impl IntoIterator<Item = (K, V)>,
) -> Result<Vec<u8>, DatasetError>
where
    K: std::fmt::Display,
    V: Serialize,
{
    let mut out = String::from("{\n");
    let mut first = true;
    for (key, value) in entries {
        if !first {
            out.push_str(",\n");
        }
        first = false;
        let key = serde_json::to_string(&key.to_string()).map_err(json_encode_error(path))?;
        let value = serde_json::to_string(&value).map_err(json_encode_error(path))?;
        out.push_str(&format!("  {key}: {value}"));
    }
    out.push_str("\n}\n");
    Ok(out.into_bytes())
}

/// Writes `entries` at `path` atomically as a [`bop_style_object`].
pub(crate) fn write_bop_style_object<K, V>(
    path: &Path,
    entries: impl IntoIterator<Item = (K, V)>,
) -> Result<(), DatasetError>
where
    K: std::fmt::Display,
    V: Serialize,
{
    let bytes = bop_style_object(path, entries)?;
    Ok(write_file_atomically(path, &bytes)?)
}

/// Writes `value` at `path` atomically as pretty-printed JSON with a final newline: the layout
/// of Glint's own JSON files.
pub(crate) fn write_pretty_json(path: &Path, value: &impl Serialize) -> Result<(), DatasetError> {
    let mut bytes = serde_json::to_vec_pretty(value).map_err(json_encode_error(path))?;
    bytes.push(b'\n');
    Ok(write_file_atomically(path, &bytes)?)
}

/// The error of encoding the contents of the file at `path` as JSON.
pub(crate) fn json_encode_error(path: &Path) -> impl Fn(serde_json::Error) -> DatasetError + '_ {
    |source| DatasetError::JsonEncode {
        path: path.to_owned(),
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pointers_name_nested_keys_and_escape_slashes() {
        let value: Value = serde_json::json!({"7": [{"a/b": [1, 2, "x"]}]});
        let root = JsonNode::root(Path::new("f.json"), &value);
        let entries = root.entries().unwrap();
        let instance = &entries[0].1.items().unwrap()[0];
        let array = instance.field("a/b").unwrap();
        let err = array.f64_array::<3>().unwrap_err();
        assert_eq!(err.key(), Some("/7/0/a~1b/2"));
        assert!(err.to_string().contains("f.json"), "{err}");
        assert!(err.to_string().contains("the string \"x\""), "{err}");
        let err = instance.field("missing").unwrap_err();
        assert_eq!(err.key(), Some("/7/0/missing"));
        assert!(array.f64_array::<2>().is_err());
    }

    #[test]
    fn integers_accept_whole_floats_and_check_range() {
        let value: Value = serde_json::json!([3, 3.0, 3.5, -1, 70000]);
        let items = JsonNode::root(Path::new("f.json"), &value).items().unwrap();
        assert_eq!(items[0].integer::<u32>().unwrap(), 3);
        assert_eq!(items[1].integer::<u32>().unwrap(), 3);
        assert!(items[2].integer::<u32>().is_err());
        assert!(items[3].integer::<u32>().is_err());
        assert_eq!(items[3].integer::<i32>().unwrap(), -1);
        assert!(items[4].integer::<u16>().is_err());
    }

    #[test]
    fn matrices_read_flat_or_in_rows() {
        let flat: Value = serde_json::json!([1, 2, 3, 4]);
        let rows: Value = serde_json::json!([[1, 2], [3, 4]]);
        let ragged: Value = serde_json::json!([[1, 2], [3]]);
        let path = Path::new("m.json");
        let expected = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            JsonNode::root(path, &flat)
                .f64_array_flattened::<4>()
                .unwrap(),
            expected
        );
        assert_eq!(
            JsonNode::root(path, &rows)
                .f64_array_flattened::<4>()
                .unwrap(),
            expected
        );
        assert!(
            JsonNode::root(path, &ragged)
                .f64_array_flattened::<4>()
                .is_err()
        );
    }

    #[test]
    fn bop_style_objects_are_valid_json() {
        let path = Path::new("o.json");
        let bytes = bop_style_object(
            path,
            [
                (1, serde_json::json!({"a": [1.5]})),
                (10, serde_json::json!(2)),
            ],
        )
        .unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert_eq!(text, "{\n  \"1\": {\"a\":[1.5]},\n  \"10\": 2\n}\n");
        let parsed: Value = serde_json::from_str(&text).unwrap();
        assert_eq!(parsed["10"], 2);
        let empty =
            String::from_utf8(bop_style_object(path, Vec::<(u32, u32)>::new()).unwrap()).unwrap();
        assert!(
            serde_json::from_str::<Value>(&empty)
                .unwrap()
                .as_object()
                .unwrap()
                .is_empty()
        );
    }
}
