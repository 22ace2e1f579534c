//! The committed fuzz corpus (`fuzz/corpus/<target>/`), replayed on the stable toolchain: every file
//! through the function its cargo-fuzz target calls (`host_compiler::fuzz`), so CI exercises what the
//! campaigns found without nightly. `write_seeds` (ignored; run with `--ignored`) writes the seed inputs
//! the campaigns started from into `fuzz/seeds/`.

use host_compiler::export::harness::{exits_image, feedforward_image, pwa_image};
use shared_types::image::{decode, encode, Terminal};
use shared_types::protocol::{encode_frame, InputVec, Reply, Request, State, MAX_FRAME};
use std::path::PathBuf;

fn fuzz_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fuzz")
}

/// What a fuzz target runs on one input.
type Entry = fn(&[u8]);

/// The targets and the function each runs.
const TARGETS: [(&str, Entry); 5] = [
    ("image_decode", host_compiler::fuzz::image),
    ("spec_parse", host_compiler::fuzz::spec),
    ("csv_readers", host_compiler::fuzz::csv),
    ("mtl_parse", host_compiler::fuzz::mtl),
    ("uart_frame", host_compiler::fuzz::uart),
];

/// The files of `fuzz/<dir>/<target>/`, sorted.
fn files(dir: &str, target: &str) -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(fuzz_dir().join(dir).join(target)) else {
        return Vec::new();
    };
    let mut v: Vec<PathBuf> = rd.filter_map(|e| e.ok().map(|e| e.path())).collect();
    v.retain(|p| p.is_file());
    v.sort();
    v
}

#[test]
fn every_corpus_file_replays_without_a_failure() {
    for (target, run) in TARGETS {
        let corpus = files("corpus", target);
        let seeds = files("seeds", target);
        assert!(
            !corpus.is_empty(),
            "fuzz/corpus/{target} is empty: the campaign's corpus is not committed"
        );
        for p in corpus.iter().chain(&seeds) {
            let data = std::fs::read(p).unwrap();
            let r = std::panic::catch_unwind(|| run(&data));
            assert!(r.is_ok(), "{target}: {} fails", p.display());
        }
        eprintln!(
            "{target}: {} corpus files, {} seeds replayed",
            corpus.len(),
            seeds.len()
        );
    }
}

fn write(target: &str, name: &str, data: &[u8]) {
    let dir = fuzz_dir().join("seeds").join(target);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), data).unwrap();
}

/// Writes the seed inputs: images of every mode (feedforward, segment exits, PWA, with a spec
/// fingerprint), the example specs, CSV traces and recordings in every dialect feature, the example
/// formulas, and request and reply frames.
#[test]
#[ignore]
fn write_seeds() {
    let imgs = [
        (
            "ff",
            feedforward_image(1, 2, 1, 1, 2, Terminal::HoldLast, 0),
        ),
        (
            "ff_multi",
            feedforward_image(2, 3, 2, 2, 3, Terminal::Fallback, 2),
        ),
        ("exits", exits_image(3, 3, 2, 2, 2, Terminal::Fallback, 1)),
        ("pwa", pwa_image(4, 2, 1, 1, 2, 6, 3)),
    ];
    for (name, b) in &imgs {
        write("image_decode", &format!("{name}.img"), b);
        let fp: Vec<u8> = (0..shared_types::image::SPEC_FINGERPRINT_LEN as u8).collect();
        let img = decode(b).unwrap().with_fingerprint(&fp).unwrap();
        let mut out = vec![0u8; img.encoded_len().unwrap()];
        encode(&img, &mut out).unwrap();
        write("image_decode", &format!("{name}_fp.img"), &out);
    }
    let ex = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let mut specs: Vec<PathBuf> = std::fs::read_dir(&ex)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    specs.sort();
    for p in &specs {
        let text = std::fs::read_to_string(p).unwrap();
        let name = p.file_name().unwrap().to_string_lossy().into_owned();
        write("spec_parse", &name, text.as_bytes());
        for line in text.lines().filter(|l| l.starts_with("formula = ")) {
            let f = line.trim_start_matches("formula = ").trim_matches('"');
            write("mtl_parse", &format!("{name}.mtl"), f.as_bytes());
        }
    }
    for (i, f) in [
        "G[0,1] x1 >= 0",
        "F[0.5, 2] (x1 > 0.2 & !(x2 < -1)) | x2 <= 3",
        "(x1 > 0) U[0,1.5] (x2 > 0)",
        "G (x1 - 2 * x2 >= 0.5 -> F[0,1] x2 > 0)",
    ]
    .iter()
    .enumerate()
    {
        write("mtl_parse", &format!("f{i}.mtl"), f.as_bytes());
    }
    for (name, text) in [
        ("trace.csv", "t,x1,x2\n0,0,1\n0.1,0.5,0\n0.2,1,-0.5\n"),
        (
            "simulate.csv",
            "# x0 = 0.1, 0\nt,x1,x2,u1,status\n0,0.1,0,0.5,ok\n0.1,0.2,0.1,0.4,ok\n",
        ),
        (
            "bom_comments.csv",
            "\u{feff}# a comment\n# x0 = 0, 1\n\nt, v1\n0, 1\n0.1, 2\n",
        ),
        (
            "recording.csv",
            "# x0 = 0.1, -0.2\nt,v1\n0,1\n0.1,2\n0.2,3\n",
        ),
    ] {
        write("csv_readers", name, text.as_bytes());
    }
    let mut buf = [0u8; MAX_FRAME];
    let state = State::from_slice(&[0.5, -1.25, 3.0]).unwrap();
    let frames: Vec<(&str, Vec<u8>)> = vec![
        (
            "step",
            encode_frame(&Request::Step { seq: 7, x: state }, &mut buf)
                .unwrap()
                .to_vec(),
        ),
        (
            "shutdown",
            encode_frame(&Request::Shutdown, &mut buf).unwrap().to_vec(),
        ),
        (
            "reply",
            encode_frame(
                &Reply {
                    seq: 3,
                    status: shared_types::eval::Status::Ok,
                    u: InputVec::from_slice(&[0.25, -0.5]).unwrap(),
                    cost: 1234,
                    location: 0,
                    monitor: None,
                },
                &mut buf,
            )
            .unwrap()
            .to_vec(),
        ),
    ];
    let mut stream = Vec::new();
    for (name, f) in &frames {
        write("uart_frame", &format!("{name}.bin"), f);
        stream.extend_from_slice(f);
        stream.push(0);
    }
    write("uart_frame", "stream.bin", &stream);
}

/// The campaign record the bench rows are read from lists every target, each with its executions.
#[test]
fn the_campaign_record_lists_every_target() {
    let text = std::fs::read_to_string(fuzz_dir().join("CAMPAIGN.md")).unwrap();
    let rows = host_compiler::benchkit::fuzz_campaign(&text).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r.target.as_str()).collect();
    let mut want: Vec<&str> = TARGETS.iter().map(|t| t.0).collect();
    let mut got = names.clone();
    want.sort();
    got.sort();
    assert_eq!(got, want);
    assert!(rows.iter().all(|r| r.executions > 0), "{rows:?}");
}
