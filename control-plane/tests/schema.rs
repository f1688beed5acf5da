//! The checked-in JSON Schemas (`docs/schema/`) are the ones the types generate.

use std::path::Path;

#[test]
fn the_checked_in_schemas_are_the_types_own() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/schema");
    let bless = std::env::var_os("BLESS").is_some();
    for (name, schema) in control_plane::schema::all() {
        let want = control_plane::schema::text(&schema);
        let path = dir.join(name);
        if bless {
            std::fs::create_dir_all(&dir).expect("docs/schema");
            std::fs::write(&path, &want).expect("write the schema");
            continue;
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == want,
            "{} is not the schema the types generate: regenerate it with \
             `BLESS=1 cargo test -p control-plane --test schema`",
            path.display()
        );
    }
}
