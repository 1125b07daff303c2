//! Edits to a spec's text that keep the rest of it as the user wrote it:
//! comments, order, blank lines and number formatting (toml_edit, the
//! editor cargo uses). Only the edited values change.

use std::fmt;
use toml_edit::{DocumentMut, Item, Table, Value};

/// One edit: `key` (`table.name`) set to `value`, or removed with `None`.
#[derive(Clone, Debug, PartialEq)]
pub struct SpecEdit {
    pub key: String,
    pub value: Option<EditValue>,
}

/// A value a form can send.
#[derive(Clone, Debug, PartialEq)]
pub enum EditValue {
    Bool(bool),
    Number(f64),
    Text(String),
    /// An array of numbers (`surface.size`), written as floats.
    Numbers(Vec<f64>),
}

/// Why an edit could not be applied: the text is no TOML document, or a
/// key is not `table.name`, or a table's place holds a value.
#[derive(Clone, Debug, PartialEq)]
pub struct EditError(pub String);

impl fmt::Display for EditError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for EditError {}

/// `text` with `edits` applied, all together (values that need each
/// other, like `surface.kind` and `surface.z`, go in one call). A value
/// equal to the one written is left as written (60.0 stays 60.0); a
/// changed one keeps its line's comment and spacing, and keeps a float
/// written as a float (60.0 → 61.0, not 61). A new key goes at the end
/// of its table, a new table at the end of the document; removing the
/// last key of a table removes the table too, unless a comment heads it.
pub fn apply_edits(text: &str, edits: &[SpecEdit]) -> Result<String, EditError> {
    let mut doc: DocumentMut = text
        .parse()
        .map_err(|e: toml_edit::TomlError| EditError(format!("the spec is no TOML: {e}")))?;
    for edit in edits {
        let (table_name, name) = edit
            .key
            .split_once('.')
            .ok_or_else(|| EditError(format!("key `{}` is not `table.name`", edit.key)))?;
        let table = table_mut(&mut doc, table_name)?;
        match &edit.value {
            None => {
                table.remove(name);
                if table.is_empty() && !commented(table) {
                    doc.remove(table_name);
                }
            }
            Some(value) => set(table, name, value),
        }
    }
    Ok(doc.to_string())
}

fn commented(table: &Table) -> bool {
    let prefix = table.decor().prefix().and_then(|p| p.as_str());
    prefix.is_some_and(|p| p.contains('#'))
}

fn table_mut<'d>(doc: &'d mut DocumentMut, name: &str) -> Result<&'d mut Table, EditError> {
    let item = doc
        .as_table_mut()
        .entry(name)
        .or_insert_with(|| Item::Table(Table::new()));
    item.as_table_mut()
        .ok_or_else(|| EditError(format!("`{name}` is a value, not a table")))
}

/// Sets `name` in `table`, unless it already holds an equal value; keeps
/// the old value's comment and spacing.
fn set(table: &mut Table, name: &str, value: &EditValue) {
    let old = table.get(name).and_then(Item::as_value);
    if old.is_some_and(|old| equal(old, value)) {
        return;
    }
    let float_before = matches!(old, Some(Value::Float(_)));
    let mut new = match value {
        EditValue::Bool(b) => Value::from(*b),
        EditValue::Text(s) => Value::from(s.as_str()),
        EditValue::Number(x) => number(*x, float_before),
        EditValue::Numbers(xs) => Value::Array(xs.iter().copied().collect()),
    };
    if let Some(old) = old {
        *new.decor_mut() = old.decor().clone();
    }
    table.insert(name, Item::Value(new));
}

/// An integral number as an integer, unless the value it replaces was a
/// float; any other number as a float.
fn number(x: f64, float_before: bool) -> Value {
    let integral = x.fract() == 0.0 && x.abs() < 2f64.powi(53);
    if integral && !float_before {
        Value::from(x as i64)
    } else {
        Value::from(x)
    }
}

fn equal(old: &Value, new: &EditValue) -> bool {
    match (old, new) {
        (Value::Boolean(a), EditValue::Bool(b)) => *a.value() == *b,
        (Value::String(a), EditValue::Text(b)) => a.value() == b,
        (Value::Float(a), EditValue::Number(b)) => *a.value() == *b,
        (Value::Integer(a), EditValue::Number(b)) => *a.value() as f64 == *b,
        (Value::Array(a), EditValue::Numbers(b)) => {
            a.len() == b.len()
                && a.iter().zip(b).all(|(a, b)| match a {
                    Value::Float(f) => *f.value() == *b,
                    Value::Integer(i) => *i.value() as f64 == *b,
                    _ => false,
                })
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn number(key: &str, x: f64) -> SpecEdit {
        SpecEdit {
            key: key.into(),
            value: Some(EditValue::Number(x)),
        }
    }

    /// The lines of `a` and `b` that differ, as (line of a, line of b).
    fn changed_lines<'t>(a: &'t str, b: &'t str) -> Vec<(&'t str, &'t str)> {
        assert_eq!(a.lines().count(), b.lines().count(), "{b}");
        a.lines().zip(b.lines()).filter(|(x, y)| x != y).collect()
    }

    /// On every shipped spec, one edit changes exactly its own line: the
    /// comments, order, blank lines and other numbers stay as written.
    #[test]
    fn one_edit_changes_one_line_of_every_shipped_spec() {
        let molds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../molds");
        let mut seen = 0;
        for entry in std::fs::read_dir(molds).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "toml") {
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            let doc: DocumentMut = text.parse().unwrap();
            let width = doc["layout"]["width"].as_float().unwrap();
            let edited = apply_edits(&text, &[number("layout.width", width + 1.0)]).unwrap();
            let changed = changed_lines(&text, &edited);
            assert_eq!(changed.len(), 1, "{}: {changed:?}", path.display());
            let (before, after) = changed[0];
            let (b, a) = (before.split_once('#'), after.split_once('#'));
            assert_eq!(b.map(|x| x.1), a.map(|x| x.1), "the comment stays");
            assert!(after.contains(&format!("{:.1}", width + 1.0)), "{after}");
            // the same value again changes nothing
            assert_eq!(
                apply_edits(&text, &[number("layout.width", width)]).unwrap(),
                text
            );
            seen += 1;
        }
        assert!(seen >= 4, "{seen} shipped specs");
    }

    /// Values that need each other go in together, a removed key goes, and
    /// a new table is added at the end.
    #[test]
    fn linked_edits_removals_and_new_tables() {
        let text = "# mine\n[surface]\nkind = \"saddle\" # a comment\nradius = 60.0\n";
        let edits = [
            SpecEdit {
                key: "surface.kind".into(),
                value: Some(EditValue::Text("formula".into())),
            },
            SpecEdit {
                key: "surface.z".into(),
                value: Some(EditValue::Text("x*y/100".into())),
            },
            SpecEdit {
                key: "surface.radius".into(),
                value: None,
            },
            SpecEdit {
                key: "view.compensate".into(),
                value: Some(EditValue::Bool(false)),
            },
            number("mesh.tolerance", 0.004),
            number("layout.width", 60.0),
        ];
        let edited = apply_edits(text, &edits).unwrap();
        assert_eq!(
            edited,
            "# mine\n[surface]\nkind = \"formula\" # a comment\nz = \"x*y/100\"\n\n\
             [view]\ncompensate = false\n\n[mesh]\ntolerance = 0.004\n\n[layout]\nwidth = 60\n"
        );
        // a key added and removed again leaves the text as it was
        let off = SpecEdit {
            key: "view.compensate".into(),
            value: Some(EditValue::Bool(false)),
        };
        let on = SpecEdit {
            key: "view.compensate".into(),
            value: None,
        };
        let toggled = apply_edits(&apply_edits(text, &[off]).unwrap(), &[on]).unwrap();
        assert_eq!(toggled, text);
        let bad = apply_edits(text, &[number("width", 1.0)]).unwrap_err();
        assert!(bad.0.contains("`width` is not `table.name`"), "{bad}");
        let value = apply_edits("a = 1\n", &[number("a.b", 1.0)]).unwrap_err();
        assert!(value.0.contains("`a` is a value"), "{value}");
    }
}
