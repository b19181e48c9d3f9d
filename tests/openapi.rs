//! `openapi.yaml` is generated from the code (utoipa annotations in `src/service/http.rs`);
//! this test fails when the committed file drifts. Regenerate with
//! `UPDATE_OPENAPI=1 cargo test --test openapi`. (The document is written as JSON, which is
//! valid YAML 1.2, so no YAML serialiser is needed.)

#[test]
fn openapi_yaml_matches_the_code() {
    let doc = physnap::service::http::openapi_document();
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/openapi.yaml");
    if std::env::var_os("UPDATE_OPENAPI").is_some() {
        std::fs::write(path, &doc).unwrap();
    }
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed == doc,
        "openapi.yaml is out of date with the code: run `UPDATE_OPENAPI=1 cargo test --test openapi` and commit it"
    );
    let v: serde_json::Value = serde_json::from_str(&doc).unwrap();
    assert!(v["openapi"].as_str().unwrap().starts_with("3.1"));
    for p in [
        "/v1/jobs",
        "/v1/jobs/{id}",
        "/v1/jobs/{id}/events",
        "/v1/jobs/{id}/cancel",
        "/v1/jobs/{id}/artifacts/{name}",
    ] {
        assert!(v["paths"].get(p).is_some(), "missing path {p}");
    }
}
