//! `motorbench ctl`: the control API for a person at a shell. Exit codes:
//! 0 success; 1 the daemon could not be reached or refused; 2 bad input;
//! 3 a followed test was aborted.

use std::path::Path;

use serde_json::Value;

use super::cli::CtlCommand;
use super::client::{Client, ClientError, Reply};

/// A failure with its exit code.
#[derive(Debug)]
pub struct CtlFailure {
    /// Exit code.
    pub code: u8,
    /// For a person.
    pub message: String,
}

impl From<ClientError> for CtlFailure {
    fn from(e: ClientError) -> CtlFailure {
        CtlFailure {
            code: 1,
            message: e.to_string(),
        }
    }
}

fn bad_input(message: String) -> CtlFailure {
    CtlFailure { code: 2, message }
}

/// The daemon's error text for a non-2xx answer.
fn refused(path: &str, reply: &Reply) -> CtlFailure {
    let v = reply.json();
    let message = v["message"]
        .as_str()
        .map(str::to_string)
        .unwrap_or_else(|| String::from_utf8_lossy(&reply.body).into_owned());
    CtlFailure {
        code: 1,
        message: format!("{path}: HTTP {}: {message}", reply.status),
    }
}

async fn get_ok(client: &Client, path: &str) -> Result<Value, CtlFailure> {
    let reply = client.get(path).await?;
    if !reply.ok() {
        return Err(refused(path, &reply));
    }
    Ok(reply.json())
}

async fn post_ok(client: &Client, path: &str, body: Option<&Value>) -> Result<Value, CtlFailure> {
    let reply = client.post(path, body).await?;
    if !reply.ok() {
        return Err(refused(path, &reply));
    }
    Ok(reply.json())
}

/// The named rig, or the only one.
async fn rig_name(client: &Client, rig: Option<String>) -> Result<String, CtlFailure> {
    if let Some(r) = rig {
        return Ok(r);
    }
    let v = get_ok(client, "/v1/rigs").await?;
    let names: Vec<String> = v["rigs"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|r| r["name"].as_str().map(str::to_string))
        .collect();
    match names.as_slice() {
        [one] => Ok(one.clone()),
        _ => Err(bad_input(format!(
            "the daemon has rigs {}: name one with --rig",
            names.join(", ")
        ))),
    }
}

fn print_json(v: &Value) {
    println!("{}", serde_json::to_string_pretty(v).expect("JSON prints"));
}

/// Print the daemon's answer `v`: as JSON with `--json`, else the one
/// line `line` makes of it.
fn print_answer(json: bool, v: &Value, line: impl FnOnce(&Value) -> String) {
    if json {
        print_json(v);
    } else {
        println!("{}", line(v));
    }
}

/// Post `action` (`estop`, `reset`) to the rig `rig` (the only one when
/// none is named) and print the answer: as JSON with `--json`, else the
/// line `line` makes of the rig's name and the answer.
async fn rig_action(
    client: &Client,
    rig: Option<String>,
    action: &str,
    json: bool,
    line: impl FnOnce(&str, &Value) -> String,
) -> Result<(), CtlFailure> {
    let rig = rig_name(client, rig).await?;
    let v = post_ok(client, &format!("/v1/rigs/{rig}/{action}"), None).await?;
    print_answer(json, &v, |v| line(&rig, v));
    Ok(())
}

fn opt_f(v: &Value, digits: usize, unit: &str) -> String {
    v.as_f64()
        .map_or_else(|| "—".to_string(), |x| format!("{x:.digits$} {unit}"))
}

/// Get the list at `path` and print it: as JSON with `--json`, else one
/// line (`line`) for each element of its array `key`.
async fn print_list(
    client: &Client,
    path: &str,
    key: &str,
    json: bool,
    line: fn(&Value) -> String,
) -> Result<(), CtlFailure> {
    let v = get_ok(client, path).await?;
    if json {
        print_json(&v);
        return Ok(());
    }
    for r in v[key].as_array().into_iter().flatten() {
        println!("{}", line(r));
    }
    Ok(())
}

/// One rig of `/v1/rigs`, for a person.
fn rig_line(r: &Value) -> String {
    let mut line = format!(
        "{:<16} {:<8} motor {}  winding ≈ {}",
        r["name"].as_str().unwrap_or("?"),
        r["state"].as_str().unwrap_or("?"),
        r["motor_id"].as_str().unwrap_or("?"),
        opt_f(&r["winding_c"], 1, "°C"),
    );
    if let Some(t) = r["running_test"].as_str() {
        line += &format!("  running {t}");
    }
    if let Some(m) = r["trip"]["message"].as_str() {
        line += &format!("  TRIPPED: {m}");
    }
    line
}

/// One record of `/v1/records`, for a person: its key results last.
fn record_line(r: &Value) -> String {
    let results = r["key_results"]["params"]
        .as_object()
        .map(|p| {
            p.iter()
                .map(|(k, v)| format!("{k}={:.4}", v.as_f64().unwrap_or(f64::NAN)))
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_default();
    format!(
        "{:<40} {:<11} {:<20} {}  {}",
        r["name"].as_str().unwrap_or("?"),
        r["outcome"].as_str().unwrap_or("?"),
        r["started_at"].as_str().unwrap_or("?"),
        r["plan"].as_str().unwrap_or(""),
        results
    )
}

/// Run one `ctl` command.
pub async fn run(client: &Client, command: CtlCommand, json: bool) -> Result<(), CtlFailure> {
    match command {
        CtlCommand::Status => print_list(client, "/v1/rigs", "rigs", json, rig_line).await,
        CtlCommand::Start {
            rig,
            test_json,
            test_file,
            follow,
        } => {
            let test: Option<Value> = match (test_json, test_file) {
                (Some(text), _) => Some(
                    serde_json::from_str(&text)
                        .map_err(|e| bad_input(format!("--test-json: {e}")))?,
                ),
                (None, Some(path)) => Some(read_test_file(&path)?),
                (None, None) => None,
            };
            if let Some(t) = &test {
                if !t.is_object() {
                    return Err(bad_input(
                        "the test override must be an object of [test] keys".into(),
                    ));
                }
            }
            let rig = rig_name(client, rig).await?;
            let body = test.map(|t| serde_json::json!({ "test": t }));
            let path = format!("/v1/rigs/{rig}/tests");
            let reply = client.post(&path, body.as_ref()).await?;
            if !reply.ok() {
                let v = reply.json();
                if let Some(running) = v["running_test"].as_str() {
                    return Err(CtlFailure {
                        code: 1,
                        message: format!("rig {rig} is busy with test {running}"),
                    });
                }
                return Err(refused(&path, &reply));
            }
            let v = reply.json();
            let id = v["id"].as_str().unwrap_or_default().to_string();
            print_answer(json, &v, |_| id.clone());
            if follow {
                follow_test(client, &id, json).await
            } else {
                Ok(())
            }
        }
        CtlCommand::Follow { id } => follow_test(client, &id, json).await,
        CtlCommand::Abort { id } => {
            let id = match id {
                Some(id) => id,
                None => {
                    let rig = rig_name(client, None).await?;
                    let v = get_ok(client, &format!("/v1/rigs/{rig}")).await?;
                    v["running_test"]
                        .as_str()
                        .map(str::to_string)
                        .ok_or_else(|| CtlFailure {
                            code: 1,
                            message: format!("rig {rig} runs no test"),
                        })?
                }
            };
            let v = post_ok(client, &format!("/v1/tests/{id}/abort"), None).await?;
            print_answer(json, &v, |v| {
                format!(
                    "{id}: {}",
                    v["stop"]["message"].as_str().unwrap_or("aborted")
                )
            });
            Ok(())
        }
        CtlCommand::Estop { rig } => {
            rig_action(client, rig, "estop", json, |rig, v| {
                format!(
                    "{rig}: {} (latched until `motorbench ctl reset`)",
                    v["trip"]["message"].as_str().unwrap_or("emergency stop")
                )
            })
            .await
        }
        CtlCommand::Reset { rig } => {
            rig_action(client, rig, "reset", json, |rig, v| {
                format!("{rig}: {}", v["state"].as_str().unwrap_or("?"))
            })
            .await
        }
        CtlCommand::Records => {
            print_list(client, "/v1/records", "records", json, record_line).await
        }
        CtlCommand::Fetch { name, out } => {
            std::fs::create_dir_all(&out)
                .map_err(|e| bad_input(format!("{}: {e}", out.display())))?;
            let entry = get_ok(client, &format!("/v1/records/{name}")).await?;
            let mut wrote = Vec::new();
            if entry["report"].is_string() {
                let dest = out.join(format!("{name}.report.json"));
                let (status, _) = client
                    .download(&format!("/v1/records/{name}/report"), &dest)
                    .await?;
                if (200..300).contains(&status) {
                    wrote.push(dest);
                }
            }
            let dest = out.join(format!("{name}.mcap"));
            let (status, bytes) = client
                .download(&format!("/v1/records/{name}/mcap"), &dest)
                .await?;
            if !(200..300).contains(&status) {
                return Err(CtlFailure {
                    code: 1,
                    message: format!("{name}: the MCAP could not be fetched (HTTP {status})"),
                });
            }
            wrote.push(dest);
            for p in &wrote {
                println!("{}", p.display());
            }
            if !json {
                eprintln!(
                    "{name}: {} ({bytes} bytes of MCAP)",
                    entry["outcome"].as_str().unwrap_or("?")
                );
            }
            Ok(())
        }
    }
}

fn read_test_file(path: &Path) -> Result<Value, CtlFailure> {
    let text =
        std::fs::read_to_string(path).map_err(|e| bad_input(format!("{}: {e}", path.display())))?;
    let table: toml::Table =
        toml::from_str(&text).map_err(|e| bad_input(format!("{}: {e}", path.display())))?;
    serde_json::to_value(table).map_err(|e| bad_input(format!("{}: {e}", path.display())))
}

/// Follow a test's live feed to its end; the exit code follows the
/// outcome.
async fn follow_test(client: &Client, id: &str, json: bool) -> Result<(), CtlFailure> {
    let path = format!("/v1/tests/{id}/events");
    let mut last_line_t = f64::NEG_INFINITY;
    let mut last_segment = None;
    let mut done: Option<Value> = None;
    let refusal = client
        .events(&path, |name, data| {
            let v: Value = serde_json::from_str(data).unwrap_or(Value::Null);
            if json {
                println!("{data}");
            } else {
                let segment = v["segment"]["index"].as_u64();
                let t = v["t_s"].as_f64().unwrap_or(0.0);
                if segment != last_segment || t - last_line_t >= 1.0 || name == "done" {
                    last_segment = segment;
                    last_line_t = t;
                    let values = &v["values"];
                    println!(
                        "t {:>7.2} s  segment {}/{} {:<22} U {}  I {}  ω {}  winding {}  ETA {}",
                        t,
                        v["segment"]["index"].as_u64().map_or(0, |i| i + 1),
                        v["segment"]["total"].as_u64().unwrap_or(0),
                        v["segment"]["label"].as_str().unwrap_or(""),
                        opt_f(&values["voltage"], 1, "V"),
                        opt_f(&values["current"], 3, "A"),
                        opt_f(&values["speed"], 1, "rad/s"),
                        opt_f(&values["winding_c"], 1, "°C"),
                        opt_f(&v["eta_s"], 1, "s"),
                    );
                }
            }
            if name == "done" {
                done = Some(v);
                return false;
            }
            true
        })
        .await?;
    if let Some(reply) = refusal {
        return Err(refused(&path, &reply));
    }
    let Some(v) = done else {
        return Err(CtlFailure {
            code: 1,
            message: format!("{id}: the live feed ended before the test did"),
        });
    };
    let outcome = v["outcome"].as_str().unwrap_or("?").to_string();
    let reason = v["reason"].as_str().unwrap_or("");
    if !json {
        println!(
            "{id}: {outcome}{}",
            if reason.is_empty() {
                String::new()
            } else {
                format!(": {reason}")
            }
        );
    }
    match outcome.as_str() {
        "completed" => Ok(()),
        "aborted" => Err(CtlFailure {
            code: 3,
            message: format!("{id} was aborted"),
        }),
        _ => Err(CtlFailure {
            code: 1,
            message: format!("{id} {outcome}"),
        }),
    }
}
