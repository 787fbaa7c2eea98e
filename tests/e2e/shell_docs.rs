//! `motorbench completions` and `motorbench man`, through the binary: the
//! bash script is valid bash and completes every subcommand and a flag of
//! `run`; the man pages are one per subcommand and name their flags.

use crate::common::{motorbench, text};

/// The subcommands `motorbench --help` lists.
fn subcommands() -> Vec<String> {
    let help = motorbench(&["--help"]);
    let (stdout, _) = text(&help);
    stdout
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|&c| c != "help")
        .map(str::to_string)
        .collect()
}

#[test]
fn bash_completion_is_valid_bash_and_knows_every_subcommand() {
    let subs = subcommands();
    assert!(subs.len() >= 8, "{subs:?}");
    let out = motorbench(&["completions", "bash"]);
    let (script, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    for sub in &subs {
        assert!(script.contains(sub.as_str()), "no {sub} in the script");
    }
    assert!(
        script.contains("--no-diagnose"),
        "run's flags are completed"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("motorbench.bash");
    std::fs::write(&path, &script).unwrap();
    let check = std::process::Command::new("bash")
        .arg("-n")
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
}

#[test]
fn man_writes_one_page_per_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    let out = motorbench(&["man", dir.path().to_str().unwrap()]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stderr}");
    let mut expected = vec!["motorbench.1".to_string()];
    expected.extend(subcommands().iter().map(|s| format!("motorbench-{s}.1")));
    let mut written: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    expected.sort();
    assert_eq!(written, expected);
    assert_eq!(stdout.lines().count(), expected.len(), "{stdout}");
    let run = std::fs::read_to_string(dir.path().join("motorbench-run.1")).unwrap();
    assert!(run.contains(".TH motorbench-run 1"), "{run}");
    assert!(run.contains("\\-\\-no\\-diagnose"), "{run}");
}

#[test]
fn an_unknown_shell_is_a_usage_error() {
    let out = motorbench(&["completions", "tcsh"]);
    let (_, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("possible values"), "{stderr}");
}
