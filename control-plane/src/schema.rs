//! The JSON Schemas of the control plane's documents, generated from their types: a field
//! added to a type is in its schema, and `tests/schema.rs` fails until the checked-in copy
//! under `docs/schema/` is regenerated (`BLESS=1 cargo test -p control-plane --test schema`).

use schemars::Schema;

/// Every document with a schema: its file name under `docs/schema/` and its schema.
pub fn all() -> Vec<(&'static str, Schema)> {
    vec![
        (
            "status.schema.json",
            schemars::schema_for!(crate::status::Status),
        ),
        (
            "report.schema.json",
            schemars::schema_for!(crate::report::RunDocument),
        ),
        (
            "up.schema.json",
            schemars::schema_for!(crate::report::UpEnded),
        ),
    ]
}

/// A schema as the file holds it: pretty JSON and a final newline.
pub fn text(schema: &Schema) -> String {
    let mut s = serde_json::to_string_pretty(schema).unwrap_or_default();
    s.push('\n');
    s
}
