//! `synth --import DIR` (issue 15): a directory stands for its `*.csv` files in sorted order (hidden
//! and other files are skipped); an empty directory and a bad file in it are bad input naming them.

use host_compiler::trajectory::csv::recordings_in;
use std::path::PathBuf;
use std::process::Command;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hc-import-dir-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn synth_import(dir: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_host-compiler"))
        .arg("synth")
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/planar-vehicle.toml"
        ))
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--import")
        .arg(dir.join("runs"))
        .arg("--quiet")
        .output()
        .unwrap()
}

const GOOD: &str = "# x0 = 0, 0, 0, 1\nt,v1,v2\n0,0.1,0.2\n0.01,0.1,0.2\n";

#[test]
fn a_directory_is_its_csv_files_in_sorted_order() {
    let d = scratch("sorted");
    for f in ["b.csv", "a.csv", ".hidden.csv", "notes.txt", "C.CSV"] {
        std::fs::write(d.join(f), GOOD).unwrap();
    }
    std::fs::create_dir(d.join("sub.csv")).unwrap();
    let names: Vec<String> = recordings_in(&d)
        .unwrap()
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["C.CSV", "a.csv", "b.csv"]);
    // A file stands for itself.
    assert_eq!(
        recordings_in(&d.join("a.csv")).unwrap(),
        vec![d.join("a.csv")]
    );
}

#[test]
fn an_empty_directory_or_a_bad_file_in_it_is_bad_input() {
    let d = scratch("bad");
    std::fs::create_dir_all(d.join("runs")).unwrap();
    let out = synth_import(&d);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the directory holds no .csv"), "{err}");
    std::fs::write(d.join("runs/a.csv"), GOOD).unwrap();
    std::fs::write(d.join("runs/b.csv"), "# x0 = 0, 0, 0, 1\nt,v1,v2\n0,x,0\n").unwrap();
    let out = synth_import(&d);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("b.csv:3:3: `x` is not a finite number"),
        "{err}"
    );
}
