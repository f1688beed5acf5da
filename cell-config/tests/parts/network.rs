use cell_config::network::*;

#[test]
fn a_cell_name_becomes_a_key_chunk() {
    let n: NetworkSettings =
        toml::from_str("users = \"u.toml\"\nlisten = [\"tls/0.0.0.0:7447\"]").expect("parses");
    let name = |cell: &str| n.line_name(cell).map(String::from);
    assert_eq!(name("Gantry UBA").as_deref(), Ok("gantry-uba"));
    assert_eq!(name(" Press #2 ").as_deref(), Ok("press--2"));
    assert!(name("***").is_err());
    let named: Result<NetworkSettings, _> = toml::from_str("users = \"u\"\nname = \"a/b\"");
    let e = named.expect_err("a/b").to_string();
    assert!(e.contains("\"a/b\" is not a cell's name"), "{e}");
}
