//! The Foxglove layouts shipped in `layouts/foxglove/` (docs/foxglove.md)
//! open what a fresh record holds: every topic a panel names is a channel
//! of a record `motorbench run` writes, every message path's field is in
//! that channel's JSON Schema, and the panel tree and the panel configs
//! name the same panels.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::common;

/// Panel types the layouts use (Foxglove's ids; `RosOut` is its Log panel).
const PANEL_TYPES: [&str; 4] = ["Plot", "StateTransitions", "RosOut", "RawMessages"];

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// Runs `motorbench run --config CONFIG` and returns its record.
fn fresh_record(config: &str, dir: &Path) -> PathBuf {
    let run = common::motorbench(&[
        "run",
        "--config",
        repo(config).to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--quiet",
        "--no-diagnose",
    ]);
    assert!(run.status.success(), "{}", common::text(&run).1);
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("run wrote an MCAP")
}

/// Every channel of `record`: topic → the `properties` of its JSON Schema.
fn channels(record: &Path) -> BTreeMap<String, Value> {
    let bytes = std::fs::read(record).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    summary
        .channels
        .values()
        .map(|c| {
            let schema: Value =
                serde_json::from_slice(&c.schema.as_ref().expect("a schema").data).unwrap();
            (c.topic.clone(), schema["properties"].clone())
        })
        .collect()
}

/// The panel ids at the leaves of a layout's panel tree.
fn leaves(node: &Value, out: &mut BTreeSet<String>) {
    match node {
        Value::String(id) => {
            out.insert(id.clone());
        }
        Value::Object(split) => {
            assert!(
                ["row", "column"].contains(&split["direction"].as_str().unwrap_or("")),
                "{split:?}"
            );
            leaves(&split["first"], out);
            leaves(&split["second"], out);
        }
        other => panic!("not a panel tree node: {other}"),
    }
}

/// Every message path (`/topic.field…`) and bare topic the panels name.
fn named_paths(config_by_id: &serde_json::Map<String, Value>) -> Vec<String> {
    let mut out = Vec::new();
    for config in config_by_id.values() {
        for p in config["paths"].as_array().into_iter().flatten() {
            out.push(p["value"].as_str().unwrap().to_string());
        }
        for key in ["topicToRender", "topicPath"] {
            if let Some(t) = config[key].as_str() {
                out.push(t.to_string());
            }
        }
        if let Some(x) = config["xAxisPath"]["value"].as_str() {
            out.push(x.to_string());
        }
    }
    out
}

/// Checks `layout` against `record`; returns how many paths it checked.
fn check(layout: &str, record: &Path) -> usize {
    let text = std::fs::read_to_string(repo(layout)).unwrap();
    let layout: Value = serde_json::from_str(&text).unwrap();
    let configs = layout["configById"].as_object().expect("configById");
    let mut tree = BTreeSet::new();
    leaves(&layout["layout"], &mut tree);
    let configured: BTreeSet<String> = configs.keys().cloned().collect();
    assert_eq!(tree, configured, "the panel tree and the configs differ");
    for id in &configured {
        let kind = id.split('!').next().unwrap();
        assert!(PANEL_TYPES.contains(&kind), "unknown panel type in {id}");
    }

    let channels = channels(record);
    let paths = named_paths(configs);
    for path in &paths {
        let end = path.find(['.', '{', '[']).unwrap_or(path.len());
        let (topic, rest) = path.split_at(end);
        let properties = channels.get(topic).unwrap_or_else(|| {
            panic!(
                "{path}: topic {topic} is not in the record ({:?})",
                channels.keys()
            )
        });
        if let Some(field) = rest.strip_prefix('.') {
            let field = field.split(['.', '[', '{']).next().unwrap();
            assert!(
                properties.get(field).is_some(),
                "{path}: {topic}'s schema has no field {field}"
            );
        }
    }
    paths.len()
}

/// Runs `config`'s test and checks `layout` against its record: at least
/// `min_paths` paths named, every one found.
fn layout_fits_a_fresh_record(config: &str, layout: &str, min_paths: usize) {
    let dir = tempfile::tempdir().unwrap();
    let record = fresh_record(config, dir.path());
    let n = check(layout, &record);
    assert!(n >= min_paths, "{layout}: {n} paths");
}

#[test]
fn the_dc_layout_names_only_what_a_dc_record_holds() {
    layout_fits_a_fresh_record("tests/mcap_corpus/seed.toml", "layouts/foxglove/dc.json", 7);
}

#[test]
fn the_im_layout_names_only_what_an_im_record_holds() {
    layout_fits_a_fresh_record("config/sim-im.toml", "layouts/foxglove/im.json", 12);
}
