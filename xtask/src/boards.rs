//! The firmware's boards: which there are, how each is built, and their flash and RAM against the budgets,
//! which are stated in `shared_types::budgets` and nowhere else ([`BUDGETS`]).
//!
//! Flash and RAM are read from the linked ELF's section headers (the `object` crate; the logic of
//! `llvm-size`/Berkeley `size`): flash is every allocated section with contents (vector table, code,
//! read-only data, the initial values of `.data`), static RAM every allocated writable section (`.data`,
//! `.bss`, `.uninit`). The RAM figure checked is static RAM plus the loop's worst-case stack: in
//! `cargo xtask test` the largest painted-stack high-water mark of every session of the HIL suite (every
//! image mode; `qemu_tests::logs::record_stack_peak`), in `cargo xtask bench` hil-bench's
//! `firmware_stack_bytes_bound`. Both are measured on mps2-an386; the loop and the evaluator are the same
//! code on every board, so the figure stands for each.
//!
//! What a firmware links depends on its image (`firmware/control-loop/build.rs`): the PWA step, the model
//! maps' interpreter and the task's monitor only when the image has them. Among images of one such
//! configuration the code is the same and flash grows with the image's length alone, so each board is
//! built with the longest image of each configuration among the shipped examples' images (the ones the
//! HIL suite synthesises from `examples/*.toml`, [`SHIPPED_IMAGES`]), which bounds the others of that
//! configuration.

use crate::{root, run, target_dir, TARGET};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Every board: a folder `firmware/boards/<name>` holding a package and binary of that name.
pub const BOARDS: &[&str] = &["mps2-an386", "nucleo-f446re"];

/// What every board must fit, with every shipped example's image (issue 16).
pub struct Budgets {
    /// Flash: code, read-only data, the image, `.data`'s initial values.
    pub flash_bytes: u64,
    /// RAM: static data and the loop's worst-case stack.
    pub ram_bytes: u64,
    /// The loop's worst-case stack alone (bench row `firmware_stack_bytes_bound`).
    pub stack_bytes: u64,
}

/// The budgets, as `shared_types::budgets` states them (the one place; `synth` reads them too).
pub const BUDGETS: Budgets = Budgets {
    flash_bytes: shared_types::budgets::FLASH_BYTES,
    ram_bytes: shared_types::budgets::RAM_BYTES,
    stack_bytes: shared_types::budgets::STACK_BYTES,
};

/// The shipped examples' images, as the HIL suite (and hil-bench) name them in `<target>/hil/images/`:
/// (file stem, the example it was synthesised from).
pub const SHIPPED_IMAGES: &[(&str, &str)] = &[
    ("planar_vehicle", "examples/planar-vehicle.toml"),
    (
        "pwa_double_integrator",
        "examples/double-integrator.toml, PWA",
    ),
    ("pwa_example_6_4", "examples/planar-vehicle-pwa-4.toml, PWA"),
    ("hybrid_4_25", "examples/hybrid-internal-4-25.toml"),
    ("hybrid_bench", "examples/hybrid-internal-4-25.toml"),
    ("hybrid_forced_cart", "examples/hybrid-forced-cart.toml"),
    (
        "hybrid_forced_cart_mtl",
        "examples/hybrid-forced-cart-mtl.toml",
    ),
    (
        "monitor_double_integrator",
        "examples/double-integrator.toml, with the task's monitor",
    ),
    (
        "planar_vehicle_monitor",
        "examples/planar-vehicle.toml, with the task's monitor",
    ),
];

/// What a firmware built for `bytes` links beyond the feedforward law: "feedforward", or the optional
/// paths its image needs joined by `+` ("PWA", "model maps", "monitor"); `None` if the image does not
/// decode (the firmware would refuse it; nothing is checked for it).
pub fn configuration(bytes: &[u8]) -> Option<String> {
    let img = shared_types::image::decode(bytes).ok()?;
    let mut parts = Vec::new();
    if img.mode() == shared_types::image::Mode::PwaFeedback {
        parts.push("PWA");
    }
    if img.model_maps().is_some() {
        parts.push("model maps");
    }
    if img.monitor().is_some() {
        parts.push("monitor");
    }
    Some(if parts.is_empty() {
        "feedforward".to_string()
    } else {
        parts.join("+")
    })
}

/// A cargo command in a board's folder (cargo reads the `.cargo/config.toml` there and in `firmware/`),
/// without the host's target settings.
pub fn board_cargo(board: &str) -> Command {
    let mut c = crate::firmware_cargo();
    c.current_dir(board_dir(board));
    c
}

/// A board's folder.
pub fn board_dir(board: &str) -> PathBuf {
    root().join("firmware").join("boards").join(board)
}

/// Where cargo puts a board's release ELF (the firmware workspace's target directory).
pub fn elf(board: &str) -> PathBuf {
    root()
        .join("firmware")
        .join("target")
        .join(TARGET)
        .join("release")
        .join(board)
}

/// `cargo build --release` of `board` with `image` embedded (`None`: the default test image); with
/// `all_paths`, every optional path linked whatever the image (model maps, the task's monitor, PWA
/// feedback: `CONTROLLER_MODEL_MAPS=1`, `CONTROLLER_MONITOR=1`, `CONTROLLER_PWA=1`, see
/// `firmware/control-loop/build.rs`); without, exactly what the image needs.
pub fn build(board: &str, image: Option<&Path>, all_paths: bool) -> Result<(), String> {
    let mut c = board_cargo(board);
    c.args(["build", "--release"]);
    match image {
        Some(p) => c.env("CONTROLLER_IMAGE", p),
        None => c.env_remove("CONTROLLER_IMAGE"),
    };
    c.env_remove("CONTROLLER_REJECTED_M")
        .env_remove("FIRMWARE_FAULT_INJECTION");
    for var in [
        "CONTROLLER_MODEL_MAPS",
        "CONTROLLER_MONITOR",
        "CONTROLLER_PWA",
    ] {
        match all_paths {
            true => c.env(var, "1"),
            false => c.env_remove(var),
        };
    }
    run(c)
}

/// Flash and static RAM of an ELF, in bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ElfSize {
    /// Allocated sections with contents (`SHF_ALLOC`, not `SHT_NOBITS`).
    pub flash: u64,
    /// Allocated writable sections (`SHF_ALLOC | SHF_WRITE`), without the stack.
    pub ram: u64,
}

/// Sizes the way `size` (Berkeley format) does: flash = text + data, RAM = data + bss.
pub fn elf_size(elf: &[u8]) -> Result<ElfSize, String> {
    use object::elf::{SHF_ALLOC, SHF_WRITE};
    use object::{Object, ObjectSection, SectionFlags, SectionKind};
    let file = object::File::parse(elf).map_err(|e| format!("reading the ELF: {e}"))?;
    let mut size = ElfSize { flash: 0, ram: 0 };
    for s in file.sections() {
        let SectionFlags::Elf { sh_flags } = s.flags() else {
            continue;
        };
        if sh_flags & u64::from(SHF_ALLOC) == 0 {
            continue;
        }
        // SHT_NOBITS sections (.bss, .uninit) take no flash.
        let nobits = matches!(
            s.kind(),
            SectionKind::UninitializedData | SectionKind::UninitializedTls
        );
        if !nobits {
            size.flash += s.size();
        }
        if sh_flags & u64::from(SHF_WRITE) != 0 {
            size.ram += s.size();
        }
    }
    Ok(size)
}

/// One board's figures.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    pub board: &'static str,
    /// What the firmware links for that image ([`configuration`]).
    pub config: String,
    /// The image it was built with (file name) and that image's length.
    pub image: String,
    pub image_bytes: u64,
    pub flash: u64,
    pub static_ram: u64,
    /// The loop's worst-case stack counted in `ram`.
    pub stack: u64,
    /// `static_ram + stack`.
    pub ram: u64,
}

/// The longest shipped image of each configuration ([`configuration`]) present in
/// `<target>/hil/images/`: (configuration, path, length), in the order of [`SHIPPED_IMAGES`]' first of
/// each.
pub fn longest_shipped_images() -> Result<Vec<(String, PathBuf, u64)>, String> {
    let dir = target_dir().join("hil").join("images");
    let mut best: Vec<(String, PathBuf, u64)> = Vec::new();
    for (stem, _) in SHIPPED_IMAGES {
        let p = dir.join(format!("{stem}.bin"));
        let Ok(bytes) = std::fs::read(&p) else {
            continue;
        };
        let Some(config) = configuration(&bytes) else {
            continue;
        };
        let len = bytes.len() as u64;
        match best.iter_mut().find(|(c, _, _)| *c == config) {
            Some(b) if len > b.2 => *b = (config, p, len),
            Some(_) => {}
            None => best.push((config, p, len)),
        }
    }
    if best.is_empty() {
        return Err(format!(
            "no shipped example's image in {} (the HIL suite writes them: cargo test -p qemu-tests)",
            dir.display()
        ));
    }
    Ok(best)
}

/// Builds every board with the longest shipped image of each configuration and sizes it; `stack` is the
/// loop's worst-case stack.
pub fn measure(stack: u64) -> Result<Vec<Figure>, String> {
    let mut figures = Vec::new();
    for (config, image, image_bytes) in longest_shipped_images()? {
        let name = image
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        println!(
            "xtask: every board with the longest shipped {config} image, {name} ({image_bytes} bytes)"
        );
        for &board in BOARDS {
            build(board, Some(&image), false)?;
            let path = elf(board);
            let bytes =
                std::fs::read(&path).map_err(|e| format!("reading {}: {e}", path.display()))?;
            let size = elf_size(&bytes).map_err(|e| format!("{}: {e}", path.display()))?;
            figures.push(Figure {
                board,
                config: config.clone(),
                image: name.clone(),
                image_bytes,
                flash: size.flash,
                static_ram: size.ram,
                stack,
                ram: size.ram + stack,
            });
        }
    }
    Ok(figures)
}

/// Prints the figures against [`BUDGETS`]; `Err` naming each board and figure over its budget.
pub fn check(figures: &[Figure]) -> Result<(), String> {
    let b = &BUDGETS;
    println!(
        "xtask: {:<14} {:<24} {:>12} {:>12} {:>11} {:>10}  image",
        "board", "configuration", "flash", "ram", "static ram", "stack"
    );
    let mut over = Vec::new();
    for f in figures {
        println!(
            "xtask: {:<14} {:<24} {:>12} {:>12} {:>11} {:>10}  {} ({} bytes)",
            f.board,
            f.config,
            format!("{}/{}", f.flash, b.flash_bytes),
            format!("{}/{}", f.ram, b.ram_bytes),
            f.static_ram,
            f.stack,
            f.image,
            f.image_bytes
        );
        if f.flash > b.flash_bytes {
            over.push(format!(
                "{}: flash {} bytes > budget {} (with image {}, {})",
                f.board, f.flash, b.flash_bytes, f.image, f.config
            ));
        }
        if f.ram > b.ram_bytes {
            over.push(format!(
                "{}: RAM {} bytes (static {} + stack {}) > budget {} (with image {}, {})",
                f.board, f.ram, f.static_ram, f.stack, b.ram_bytes, f.image, f.config
            ));
        }
    }
    if let Some(f) = figures.first() {
        if f.stack > b.stack_bytes {
            over.push(format!(
                "the loop's stack: {} bytes > budget {}",
                f.stack, b.stack_bytes
            ));
        }
    }
    if over.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "over budget (xtask/src/boards.rs BUDGETS):\n  {}",
            over.join("\n  ")
        ))
    }
}

/// The largest stack high-water mark the HIL suite recorded (`<target>/hil/stack-peaks.txt`, one
/// `<elf> <bytes>` line per session).
pub fn hil_stack_peak() -> Result<u64, String> {
    let path = stack_peaks_file();
    let text = std::fs::read_to_string(&path).map_err(|e| {
        format!(
            "no stack figure: {} ({e}); the HIL suite writes it",
            path.display()
        )
    })?;
    text.lines()
        .filter_map(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        .max()
        .ok_or_else(|| format!("no stack figure in {}", path.display()))
}

/// Where the HIL suite records each session's stack high-water mark (qemu-tests' `logs::stack_peaks_file`).
pub fn stack_peaks_file() -> PathBuf {
    target_dir().join("hil").join("stack-peaks.txt")
}

/// The bench rows `board_<name>_flash_bytes` and `board_<name>_ram_bytes` (name with `_` for `-`): each
/// board's largest figure over the configurations.
pub fn rows(figures: &[Figure]) -> Vec<serde_json::Value> {
    let mut rows = Vec::new();
    let mut boards: Vec<&str> = Vec::new();
    for f in figures {
        if !boards.contains(&f.board) {
            boards.push(f.board);
        }
    }
    for board in boards {
        let mine = || figures.iter().filter(move |f| f.board == board);
        let (Some(fl), Some(ra)) = (mine().max_by_key(|f| f.flash), mine().max_by_key(|f| f.ram))
        else {
            continue;
        };
        let name = board.replace('-', "_");
        let f = fl;
        rows.push(serde_json::json!({
            "name": format!("board_{name}_flash_bytes"),
            "value": f.flash,
            "unit": format!(
                "bytes (image {}, {}; budget {})",
                f.image, f.config, BUDGETS.flash_bytes
            ),
        }));
        let f = ra;
        rows.push(serde_json::json!({
            "name": format!("board_{name}_ram_bytes"),
            "value": f.ram,
            "unit": format!(
                "bytes (static {} + stack bound {}, image {}, {}; budget {})",
                f.static_ram, f.stack, f.image, f.config, BUDGETS.ram_bytes
            ),
        }));
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figure(board: &'static str, flash: u64, static_ram: u64, stack: u64) -> Figure {
        Figure {
            board,
            config: "feedforward".into(),
            image: "x.bin".into(),
            image_bytes: 1,
            flash,
            static_ram,
            stack,
            ram: static_ram + stack,
        }
    }

    #[test]
    fn the_check_names_the_board_and_the_figure_over_budget() {
        assert!(check(&[figure("a", 1000, 100, 2000)]).is_ok());
        let e = check(&[
            figure("mps2-an386", 1000, 100, 2000),
            figure("nucleo-f446re", 200_000, 31 * 1024, 2000),
        ])
        .unwrap_err();
        assert!(
            e.contains("nucleo-f446re: flash 200000 bytes > budget 131072"),
            "{e}"
        );
        assert!(e.contains("nucleo-f446re: RAM 33744 bytes"), "{e}");
        assert!(!e.contains("mps2-an386"), "{e}");
        let e = check(&[figure("a", 1, 1, 9000)]).unwrap_err();
        assert!(e.contains("stack: 9000 bytes > budget 8192"), "{e}");
    }

    #[test]
    fn rows_give_each_board_its_largest_figure_over_the_configurations() {
        let mut big = figure("a", 30, 5, 1);
        big.config = "PWA".into();
        let r = rows(&[figure("a", 10, 20, 30), big]);
        assert_eq!(r.len(), 2);
        assert_eq!(r[0]["value"], 30);
        assert!(r[0]["unit"].as_str().unwrap().contains("PWA"), "{}", r[0]);
        assert_eq!(r[1]["value"], 50);
    }

    #[test]
    fn rows_are_named_after_the_board() {
        let r = rows(&[figure("nucleo-f446re", 10, 20, 30)]);
        assert_eq!(r[0]["name"], "board_nucleo_f446re_flash_bytes");
        assert_eq!(r[0]["value"], 10);
        assert_eq!(r[1]["name"], "board_nucleo_f446re_ram_bytes");
        assert_eq!(r[1]["value"], 50);
    }
}
