//! The README's "Pipelines" block, copied verbatim from README.md and run with `bash -e` on the
//! shipped files it names: a newcomer's first commands must work as written.

mod common;

/// The first ```bash block after the "## Pipelines" heading.
fn pipelines_block(readme: &str) -> String {
    let section = &readme[readme.find("## Pipelines").expect("README has a Pipelines section")..];
    let start = section.find("```bash\n").expect("a bash block") + "```bash\n".len();
    let len = section[start..].find("```").expect("the block ends");
    section[start..start + len].to_string()
}

#[test]
fn readme_pipelines_run_verbatim_on_the_shipped_data() {
    if common::fixture("citygml/nrw/LoD2_32_332_5729_1_NW.gml").is_none()
        || common::fixture("terrain/lidR_Topography.laz").is_none()
    {
        return;
    }
    let readme = std::fs::read_to_string(common::repo_root().join("README.md")).unwrap();
    let script = pipelines_block(&readme);
    let dir = common::tempdir();
    let o = common::bash_with_geofit(dir.path()).args(["-euo", "pipefail", "-c", &script]).output().expect("bash");
    assert!(o.status.success(), "README pipelines failed ({:?}):\n{}", o.status, String::from_utf8_lossy(&o.stderr));
    for out in [
        "healed.gml",
        "heal.json",
        "findings.json",
        "healed.glb",
        "adjusted.gml",
        "grid.tif",
        "grid.tmesh",
        "fitted.tif",
        "err.png",
        "grid.glb",
        "sphere.glb",
    ] {
        let len = std::fs::metadata(dir.path().join(out)).map(|m| m.len()).unwrap_or(0);
        assert!(len > 0, "README pipelines wrote no {out}");
    }
    let findings: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("findings.json")).unwrap()).unwrap();
    assert!(findings.is_object(), "validate --json wrote one JSON object: {findings}");
}
