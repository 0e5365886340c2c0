//! Fuzzing of every file loader (issue #13), on stable in `cargo test`: proptest generates
//! mutations of the seed files in `tests/fuzz-corpus/<target>/` (bit flips, byte overwrites,
//! truncation, deletion, duplication, splices with another seed, token swaps with hostile values
//! — huge numbers, NaN, infinities, empty, null, wrong types, very long strings — and deep
//! nesting), and each loader must return `Ok` or a typed error with a non-empty message, never
//! panic (`std::panic::catch_unwind`). The PNG target also edits decoded pixels (crops, noise,
//! inversion, flat fills) and runs detection and the board pose on what decodes.
//!
//! Bounds: each target runs a fixed number of cases and stops early when its time budget is
//! spent, so the whole file stays well under a minute in a debug build; every target prints its
//! executions and time. `HANDEYE_FUZZ_SCALE=10` runs ten times the cases and budget (a longer
//! local or nightly run); `HANDEYE_FUZZ_SEED=<n>` changes the generator seed (default 0, so CI
//! runs are reproducible).
//!
//! A panicking input is written to `$CARGO_TARGET_TMPDIR/fuzz-crashes/` and the target fails;
//! keep such inputs in `tests/fuzz-corpus/crashes/` with a regression test below. Found here: the
//! AprilTag C library's worker pool (apriltag-sys 0.3) races when a detector with `threads > 1`
//! is created and used, and now and then crashed the process (about once in a few thousand ViSP
//! imports, whatever the input); more than one detector thread is now refused
//! (`crash_detector_worker_pool_race_more_threads_are_refused`).
//!
//! Seeds: the repo's `configs/` and `tests/data/` files, session records from a 6-pose run of
//! `configs/sim-cell.yaml` (trimmed), and small hand-written files for the other formats; the PNG
//! seeds are made by the ignored `regenerate_png_seeds` test.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use handeye_config::CellConfig;
use handeye_core::camera_model::CameraModel;
use handeye_core::geometry::PoseYaml;
use handeye_formats::import::{
    import_csv_pairs, import_csv_two_files, import_moveit_json, import_visp, read_visp_camera_xml,
    read_visp_pose, CsvOptions, CsvPoseForm, VispOptions,
};
use handeye_plan::Plan;
use handeye_records::dataset::Dataset;
use handeye_records::result::ResultFile;
use handeye_records::SessionFolder;
use handeye_robot::recorded::load_recorded_poses;
use handeye_vision::detect::load_gray_image;
use handeye_vision::{estimate_board_pose, Board, DetectorOptions, TagDetector};
use image::{GrayImage, ImageFormat, Luma};
use proptest::collection::vec;
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};

use crate::util;

use util::repo;

/// Detector settings of the fuzz targets: one worker thread, so the AprilTag worker-pool race
/// (see the module docs) cannot kill the run; the parsing and detection paths are the same.
fn detector_options() -> DetectorOptions {
    DetectorOptions {
        threads: 1,
        ..DetectorOptions::default()
    }
}

/// The smallest image side mutations make. Every size reaches the detector: images too small for
/// it are refused with an error before the C code sees them (#13 item 4).
const MIN_DETECTOR_SIDE: u32 = 1;

/// Values a token is swapped for: numbers at and beyond `f64` limits, non-numbers, empty and
/// null, wrong types, YAML syntax that changes the document's shape.
const HOSTILE: &[&str] = &[
    "1e300",
    "-1e300",
    "1e-300",
    "1.7976931348623157e308",
    "1e309",
    "-1e309",
    "4.9e-324",
    ".nan",
    "NaN",
    ".inf",
    "-.inf",
    "inf",
    "0",
    "-0",
    "-1",
    "255",
    "256",
    "65536",
    "4294967296",
    "18446744073709551616",
    "99999999999999999999999999999999",
    "",
    "~",
    "null",
    "[]",
    "{}",
    "\"\"",
    "true",
    "x",
    "[1, 2]",
    "[1e300, 1e300, 1e300]",
    "[.nan, .nan, .nan]",
    "{w: 1}",
    "&a 1",
    "*a",
    "!!binary AAAA",
    "eye_to_hand",
    "aprilgrid",
    "- ",
    ": ",
    "\n",
    "\0",
    "é",
    ",",
    "<",
    ">",
    "\"",
];

/// One edit of a seed file.
#[derive(Debug, Clone)]
enum Mutation {
    /// Flip one bit (position taken modulo the length).
    FlipBit { at: u32, bit: u8 },
    /// Overwrite one byte.
    SetByte { at: u32, value: u8 },
    /// Cut the file here.
    Truncate { at: u32 },
    /// Remove a run of bytes.
    Delete { at: u32, len: u8 },
    /// Repeat a run of bytes in place.
    Duplicate { at: u32, len: u16 },
    /// Insert a piece of another seed.
    Splice {
        other: u8,
        from: u32,
        len: u16,
        at: u32,
    },
    /// Replace the n-th token (a run of letters, digits, `_ . + -`) with a hostile value.
    SwapToken { nth: u16, with: u8 },
    /// Replace the n-th token with a value nested `depth` levels deep (flow lists or maps).
    Nest { nth: u16, depth: u16, maps: bool },
    /// Replace the n-th token with a very long word.
    LongToken { nth: u16, len: u32 },
    /// Decode as an image, edit the pixels, encode as PNG again (no effect if it does not
    /// decode).
    Pixels(PixelEdit),
}

/// Pixel-level edits for the detector target.
#[derive(Debug, Clone)]
enum PixelEdit {
    /// Crop to a window (sides at least [`MIN_DETECTOR_SIDE`]).
    Crop { x: u16, y: u16, w: u16, h: u16 },
    /// Add uniform noise of this amplitude.
    Noise { amplitude: u8, seed: u32 },
    /// Invert every grey level.
    Invert,
    /// Fill with one grey level.
    Fill(u8),
    /// Paint every k-th row or column.
    Stripes { period: u8, rows: bool, level: u8 },
    /// Nearest-neighbour resize to a new size (sides at least [`MIN_DETECTOR_SIDE`]).
    Resize { w: u16, h: u16 },
}

fn pixel_edit() -> impl Strategy<Value = PixelEdit> {
    prop_oneof![
        (any::<u16>(), any::<u16>(), any::<u16>(), any::<u16>())
            .prop_map(|(x, y, w, h)| PixelEdit::Crop { x, y, w, h }),
        (any::<u8>(), any::<u32>())
            .prop_map(|(amplitude, seed)| PixelEdit::Noise { amplitude, seed }),
        Just(PixelEdit::Invert),
        any::<u8>().prop_map(PixelEdit::Fill),
        (1u8..16, any::<bool>(), any::<u8>()).prop_map(|(period, rows, level)| {
            PixelEdit::Stripes {
                period,
                rows,
                level,
            }
        }),
        (16u16..700, 16u16..500).prop_map(|(w, h)| PixelEdit::Resize { w, h }),
    ]
}

fn byte_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<u32>(), 0u8..8).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        (any::<u32>(), any::<u8>()).prop_map(|(at, value)| Mutation::SetByte { at, value }),
        any::<u32>().prop_map(|at| Mutation::Truncate { at }),
        (any::<u32>(), any::<u8>()).prop_map(|(at, len)| Mutation::Delete { at, len }),
        (any::<u32>(), 0u16..512).prop_map(|(at, len)| Mutation::Duplicate { at, len }),
        (any::<u8>(), any::<u32>(), 0u16..512, any::<u32>()).prop_map(|(other, from, len, at)| {
            Mutation::Splice {
                other,
                from,
                len,
                at,
            }
        }),
    ]
}

/// Mutations for text formats: byte edits plus token swaps, weighted towards the token swaps
/// (they reach the validation code behind the parser).
fn text_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        3 => byte_mutation(),
        5 => (any::<u16>(), any::<u8>()).prop_map(|(nth, with)| Mutation::SwapToken { nth, with }),
        1 => (any::<u16>(), 1u16..3000, any::<bool>())
            .prop_map(|(nth, depth, maps)| Mutation::Nest { nth, depth, maps }),
        1 => (any::<u16>(), 1u32..100_000).prop_map(|(nth, len)| Mutation::LongToken { nth, len }),
    ]
}

/// Mutations for images: mostly pixel edits (byte edits rarely survive PNG's checksums).
fn image_mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        4 => pixel_edit().prop_map(Mutation::Pixels),
        1 => byte_mutation(),
    ]
}

fn is_token_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || matches!(b, b'_' | b'.' | b'+' | b'-')
}

/// Byte ranges of the tokens of `bytes`.
fn tokens(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &b) in bytes.iter().enumerate() {
        match (is_token_byte(b), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, bytes.len()));
    }
    out
}

fn replace_token(bytes: &mut Vec<u8>, nth: u16, with: &[u8]) {
    let t = tokens(bytes);
    if t.is_empty() {
        bytes.extend_from_slice(with);
        return;
    }
    let (a, b) = t[nth as usize % t.len()];
    bytes.splice(a..b, with.iter().copied());
}

fn at(pos: u32, len: usize) -> usize {
    if len == 0 {
        0
    } else {
        pos as usize % (len + 1)
    }
}

fn apply(bytes: &mut Vec<u8>, seeds: &[Vec<u8>], m: &Mutation) {
    let n = bytes.len();
    match *m {
        Mutation::FlipBit { at: p, bit } => {
            if n > 0 {
                bytes[p as usize % n] ^= 1 << bit;
            }
        }
        Mutation::SetByte { at: p, value } => {
            if n > 0 {
                bytes[p as usize % n] = value;
            }
        }
        Mutation::Truncate { at: p } => bytes.truncate(at(p, n)),
        Mutation::Delete { at: p, len } => {
            let a = at(p, n);
            let b = (a + len as usize).min(n);
            bytes.drain(a..b);
        }
        Mutation::Duplicate { at: p, len } => {
            let a = at(p, n);
            let b = (a + len as usize).min(n);
            let piece = bytes[a..b].to_vec();
            bytes.splice(b..b, piece);
        }
        Mutation::Splice {
            other,
            from,
            len,
            at: p,
        } => {
            let other = &seeds[other as usize % seeds.len()];
            let a = at(from, other.len());
            let b = (a + len as usize).min(other.len());
            let i = at(p, n);
            bytes.splice(i..i, other[a..b].iter().copied());
        }
        Mutation::SwapToken { nth, with } => replace_token(
            bytes,
            nth,
            HOSTILE[with as usize % HOSTILE.len()].as_bytes(),
        ),
        Mutation::Nest { nth, depth, maps } => {
            let depth = depth as usize;
            let nested = if maps {
                format!("{}1{}", "{a: ".repeat(depth), "}".repeat(depth))
            } else {
                format!("{}1{}", "[".repeat(depth), "]".repeat(depth))
            };
            replace_token(bytes, nth, nested.as_bytes());
        }
        Mutation::LongToken { nth, len } => {
            replace_token(bytes, nth, "9".repeat(len as usize).as_bytes())
        }
        Mutation::Pixels(ref edit) => {
            if let Ok(decoded) = image::load_from_memory(bytes) {
                let edited = edit_pixels(decoded.into_luma8(), edit);
                let mut png = Vec::new();
                if edited
                    .write_to(&mut std::io::Cursor::new(&mut png), ImageFormat::Png)
                    .is_ok()
                {
                    *bytes = png;
                }
            }
        }
    }
}

fn edit_pixels(mut img: GrayImage, edit: &PixelEdit) -> GrayImage {
    let (w, h) = img.dimensions();
    match *edit {
        PixelEdit::Crop { x, y, w: cw, h: ch } => {
            let min = MIN_DETECTOR_SIDE;
            if w < min || h < min {
                return img;
            }
            let cw = (cw as u32 % (w - min + 1)) + min;
            let ch = (ch as u32 % (h - min + 1)) + min;
            let x = x as u32 % (w - cw + 1);
            let y = y as u32 % (h - ch + 1);
            image::imageops::crop_imm(&img, x, y, cw, ch).to_image()
        }
        PixelEdit::Noise { amplitude, seed } => {
            let mut state = seed as u64 | 1;
            for p in img.pixels_mut() {
                // xorshift: a cheap deterministic pixel noise, not a statistical claim.
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let delta = (state % (2 * amplitude as u64 + 1)) as i32 - amplitude as i32;
                p.0[0] = (p.0[0] as i32 + delta).clamp(0, 255) as u8;
            }
            img
        }
        PixelEdit::Invert => {
            image::imageops::invert(&mut img);
            img
        }
        PixelEdit::Fill(level) => {
            for p in img.pixels_mut() {
                *p = Luma([level]);
            }
            img
        }
        PixelEdit::Stripes {
            period,
            rows,
            level,
        } => {
            for (x, y, p) in img.enumerate_pixels_mut() {
                let k = if rows { y } else { x };
                if k % period as u32 == 0 {
                    *p = Luma([level]);
                }
            }
            img
        }
        PixelEdit::Resize { w: nw, h: nh } => {
            image::imageops::resize(&img, nw as u32, nh as u32, image::imageops::Nearest)
        }
    }
}

/// The message of an error and all its sources, as a person would read it.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

/// What one loader call did.
enum Outcome {
    Ok,
    /// A typed error, its message (top level) and the full chain.
    Err {
        top: String,
        chain: String,
    },
}

fn err<E: std::error::Error>(e: &E) -> Outcome {
    Outcome::Err {
        top: e.to_string(),
        chain: chain(e),
    }
}

fn outcome<T, E: std::error::Error>(r: &Result<T, E>) -> Outcome {
    match r {
        Ok(_) => Outcome::Ok,
        Err(e) => err(e),
    }
}

/// One fuzz target: where its seeds are, how many cases, its time budget.
struct Target {
    name: &'static str,
    cases: u32,
    budget: Duration,
    image: bool,
}

fn scale() -> f64 {
    std::env::var("HANDEYE_FUZZ_SCALE")
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .unwrap_or(1.0)
}

fn corpus() -> PathBuf {
    repo().join("tests/fuzz-corpus")
}

/// Every file under `dir`, as (path relative to `dir`, bytes), sorted.
fn seed_files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(PathBuf, Vec<u8>)>) {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("corpus folder {}: {e}", dir.display()))
            .map(|e| e.unwrap().path())
            .collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                let bytes = std::fs::read(&p).unwrap();
                out.push((p.strip_prefix(root).unwrap().to_path_buf(), bytes));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    assert!(!out.is_empty(), "no seeds in {}", dir.display());
    out
}

fn generator_seed(target: &str) -> [u8; 32] {
    let base: u64 = std::env::var("HANDEYE_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    // FNV-1a of the target name, so targets do not share a stream.
    let mut h: u64 = 0xcbf2_9ce4_8422_2325 ^ base;
    for b in target.bytes() {
        h = (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
    }
    let mut seed = [0u8; 32];
    for (i, chunk) in seed.chunks_mut(8).enumerate() {
        chunk.copy_from_slice(&h.wrapping_add(i as u64).to_le_bytes());
    }
    seed
}

/// Runs `target`: each case mutates one seed and calls `run(scratch_dir, seed_relative_path,
/// bytes)` inside `catch_unwind`. Fails on a seed that does not load as it is, a panic (saving
/// the input), an empty error message or no case run.
fn fuzz(target: Target, run: impl Fn(&Path, &Path, &[u8]) -> Outcome) {
    let seeds = seed_files(&corpus().join(target.name));
    let seed_bytes: Vec<Vec<u8>> = seeds.iter().map(|(_, b)| b.clone()).collect();
    let scratch = tempfile::tempdir().unwrap();
    let crashes = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fuzz-crashes");
    let cases = ((target.cases as f64) * scale()).ceil() as u32;
    let budget = target.budget.mul_f64(scale());
    // The seeds themselves load: otherwise every mutation would only reach the parser's first
    // error and the target would test little.
    for (relative, bytes) in &seeds {
        if let Outcome::Err { chain, .. } = run(scratch.path(), relative, bytes) {
            panic!(
                "{}: seed {} does not load: {chain}",
                target.name,
                relative.display()
            );
        }
    }
    let (executed, ok, errors, over_budget, saved) = (
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
        AtomicUsize::new(0),
    );
    let mutations = if target.image {
        vec(image_mutation(), 1..4).boxed()
    } else {
        vec(text_mutation(), 1..5).boxed()
    };
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 64,
        max_shrink_time: 20_000,
        ..Config::default()
    };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &generator_seed(target.name));
    let mut runner = TestRunner::new_with_rng(config, rng);
    let start = Instant::now();
    let result = runner.run(
        &(0..seeds.len(), mutations),
        |(index, edits): (usize, Vec<Mutation>)| {
            if start.elapsed() > budget {
                over_budget.fetch_add(1, Ordering::Relaxed);
                return Ok(());
            }
            let (relative, seed) = &seeds[index];
            let mut bytes = seed.clone();
            for m in &edits {
                apply(&mut bytes, &seed_bytes, m);
            }
            // Every case rewrites all the files it uses, so the folder is reused as it is.
            let case_dir = scratch.path();
            executed.fetch_add(1, Ordering::Relaxed);
            let result = catch_unwind(AssertUnwindSafe(|| run(case_dir, relative, &bytes)));
            match result {
                Ok(Outcome::Ok) => {
                    ok.fetch_add(1, Ordering::Relaxed);
                    Ok(())
                }
                Ok(Outcome::Err { top, chain }) => {
                    errors.fetch_add(1, Ordering::Relaxed);
                    if top.trim().is_empty() {
                        Err(TestCaseError::fail(format!(
                            "{}: empty error message (chain: {chain:?}) for a mutation of {}",
                            target.name,
                            relative.display()
                        )))
                    } else {
                        Ok(())
                    }
                }
                Err(panic) => {
                    let message = panic
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default();
                    let n = saved.fetch_add(1, Ordering::Relaxed);
                    std::fs::create_dir_all(&crashes).unwrap();
                    let file = crashes.join(format!(
                        "{}-{n:03}-{}",
                        target.name,
                        relative.to_string_lossy().replace('/', "_")
                    ));
                    std::fs::write(&file, &bytes).unwrap();
                    Err(TestCaseError::fail(format!(
                        "{}: panic `{message}` on a mutation of {} (input saved to {})",
                        target.name,
                        relative.display(),
                        file.display()
                    )))
                }
            }
        },
    );
    let elapsed = start.elapsed();
    let executed = executed.load(Ordering::Relaxed);
    eprintln!(
        "fuzz {:<16} {executed:>6} executions in {:>6.2} s ({:>5.0}/s): {} Ok, {} typed Err; {} of {cases} cases not run (budget {:.0} s); {} seeds",
        target.name,
        elapsed.as_secs_f64(),
        executed as f64 / elapsed.as_secs_f64().max(1e-9),
        ok.load(Ordering::Relaxed),
        errors.load(Ordering::Relaxed),
        over_budget.load(Ordering::Relaxed),
        budget.as_secs_f64(),
        seeds.len(),
    );
    if let Err(e) = result {
        panic!("fuzz target {} failed: {e}", target.name);
    }
    assert!(executed > 0, "{}: nothing ran", target.name);
}

fn text_target(name: &'static str, cases: u32) -> Target {
    Target {
        name,
        cases,
        budget: Duration::from_secs(4),
        image: false,
    }
}

/// Writes `bytes` to `dir/<file name of relative>` and returns that path.
fn write_case(dir: &Path, relative: &Path, bytes: &[u8]) -> PathBuf {
    let path = dir.join(relative.file_name().unwrap());
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Cell configs: parsed and validated; a valid one also gives its settle `Duration`.
fn load_config(path: &Path) -> Outcome {
    match CellConfig::load(path) {
        Err(e) => err(&e),
        Ok(config) => {
            let _ = config.settle();
            let _ = config.camera().sim_lens();
            Outcome::Ok
        }
    }
}

#[test]
fn fuzz_cell_config() {
    fuzz(text_target("config", 2500), |dir, rel, bytes| {
        load_config(&write_case(dir, rel, bytes))
    });
}

#[test]
fn fuzz_board() {
    fuzz(text_target("board", 2500), |dir, rel, bytes| {
        outcome(&Board::load(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_camera_intrinsics() {
    fuzz(text_target("camera_model", 2500), |dir, rel, bytes| {
        outcome(&CameraModel::load(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_plan() {
    fuzz(text_target("plan", 2500), |dir, rel, bytes| {
        outcome(&Plan::load(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_pose_yaml_forms() {
    fuzz(
        text_target("pose", 4000),
        |_, _, bytes| match serde_yaml_ng::from_slice::<PoseYaml>(bytes) {
            Err(e) => err(&e),
            Ok(pose) => outcome(&pose.to_pose("T_base_flange")),
        },
    );
}

#[test]
fn fuzz_dataset() {
    fuzz(text_target("dataset", 2500), |dir, rel, bytes| {
        outcome(&Dataset::load(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_recorded_robot_poses() {
    fuzz(text_target("recorded_poses", 2500), |dir, rel, bytes| {
        outcome(&load_recorded_poses(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_result_file() {
    fuzz(text_target("result", 1000), |dir, rel, bytes| {
        let path = write_case(dir, rel, bytes);
        match ResultFile::load(&path) {
            Err(e) => err(&e),
            Ok(result) => match result.mounts(&path) {
                Err(e) => err(&e),
                Ok(_) => outcome(&result.to_calibration(&path)),
            },
        }
    });
}

/// A session folder (`session.yaml`, `poses/NNN.yaml`, `samples.yaml`) with one of its files
/// mutated, read the way `--resume` and `replay` read it.
#[test]
fn fuzz_session_folder_records() {
    let seeds = corpus().join("session");
    let originals = seed_files(&seeds);
    fuzz(text_target("session", 2000), |dir, rel, bytes| {
        for (path, original) in &originals {
            let to = dir.join(path);
            std::fs::create_dir_all(to.parent().unwrap()).unwrap();
            std::fs::write(&to, if path == rel { bytes } else { original }).unwrap();
        }
        let folder = match SessionFolder::open(dir) {
            Ok(f) => f,
            Err(e) => return err(&e),
        };
        if let Err(e) = folder.read_manifest() {
            return err(&e);
        }
        // Reading a record checks its poses too.
        if let Err(e) = folder.read_visits() {
            return err(&e);
        }
        outcome(&Dataset::load(&folder.samples_path()))
    });
}

#[test]
fn fuzz_csv_importers() {
    let other = tempfile::tempdir().unwrap();
    let camera_rows = other.path().join("camera.csv");
    std::fs::write(
        &camera_rows,
        "0.01,0.02,0.6,0,0.1,0\n-0.02,0.01,0.62,0.05,0,0.1\n0.03,-0.01,0.58,-0.1,0.05,0\n",
    )
    .unwrap();
    fuzz(text_target("csv", 1500), |dir, rel, bytes| {
        let path = write_case(dir, rel, bytes);
        // Ok when some reading of the file works; otherwise its last error. Every error is
        // checked for a message on the way.
        let mut any_ok = false;
        let mut last = None;
        for form in [CsvPoseForm::Quaternion, CsvPoseForm::RotationVector] {
            for millimetres in [false, true] {
                let options = CsvOptions { form, millimetres };
                for result in [
                    import_csv_pairs(&path, &options),
                    import_csv_two_files(&path, &camera_rows, &options),
                ] {
                    match result {
                        Ok(_) => any_ok = true,
                        Err(e) => {
                            if e.to_string().trim().is_empty() {
                                return err(&e);
                            }
                            last = Some(err(&e));
                        }
                    }
                }
            }
        }
        match last {
            Some(e) if !any_ok => e,
            _ => Outcome::Ok,
        }
    });
}

#[test]
fn fuzz_moveit_json() {
    fuzz(text_target("moveit_json", 2500), |dir, rel, bytes| {
        outcome(&import_moveit_json(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_visp_pose() {
    fuzz(text_target("visp_pose", 2500), |dir, rel, bytes| {
        outcome(&read_visp_pose(&write_case(dir, rel, bytes)))
    });
}

#[test]
fn fuzz_visp_camera_xml() {
    fuzz(text_target("visp_camera_xml", 2500), |dir, rel, bytes| {
        outcome(&read_visp_camera_xml(&write_case(dir, rel, bytes)))
    });
}

/// A ViSP data folder (pose vectors, intrinsics XML, images) with one of its files mutated,
/// imported with detection of the 2x2 board.
#[test]
fn fuzz_visp_folder_import() {
    let originals = seed_files(&corpus().join("visp_folder"));
    let board = Board::load(&repo().join("configs/targets/aprilgrid-2x2-example.yaml")).unwrap();
    fuzz(
        Target {
            budget: Duration::from_secs(5),
            ..text_target("visp_folder", 600)
        },
        |dir, rel, bytes| {
            for (path, original) in &originals {
                let content = if path == rel { bytes } else { original };
                std::fs::write(dir.join(path), content).unwrap();
            }
            let options = VispOptions {
                setup: handeye_core::setup::Setup::EyeToHand,
                board: board.clone().into(),
                camera: None,
                detector: detector_options(),
                skip_unfound: bytes.len() % 2 == 0,
            };
            outcome(&import_visp(dir, &options))
        },
    );
}

/// A camera model for an image of `width` x `height` (the sim lens, scaled).
fn model_for(width: u32, height: u32) -> CameraModel {
    let f = 0.8 * width.max(height) as f64;
    CameraModel {
        width,
        height,
        fx: f,
        fy: f,
        cx: (width as f64 - 1.0) / 2.0,
        cy: (height as f64 - 1.0) / 2.0,
        distortion: handeye_core::camera_model::Distortion::None,
    }
}

/// PNG frames: decode, detect the board, estimate its pose.
#[test]
fn fuzz_png_frames_for_the_detector() {
    let board = Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let detector = TagDetector::spawn(&board, detector_options()).unwrap();
    fuzz(
        Target {
            name: "png",
            cases: 3000,
            budget: Duration::from_secs(8),
            image: true,
        },
        |dir, rel, bytes| {
            let image = match load_gray_image(&write_case(dir, rel, bytes)) {
                Ok(image) => image,
                Err(e) => return err(&e),
            };
            let (w, h) = image.dimensions();
            match detector.detect(&image) {
                Err(e) => err(&e),
                Ok(detection) => {
                    if detection.tags.is_empty() {
                        return Outcome::Ok;
                    }
                    outcome(&estimate_board_pose(&board, &model_for(w, h), &detection))
                }
            }
        },
    );
}

/// Makes the PNG seeds (run by hand: `cargo test --test fuzz -- --ignored regenerate`): the
/// README's 2x2 board picture scaled down (grey and RGB), and a 320x180 simulated frame of the
/// 6x6 grid rendered through the sim lens scaled to that size.
#[test]
#[ignore = "writes the PNG seeds into tests/fuzz-corpus/png; run by hand"]
fn regenerate_png_seeds() {
    use handeye_camera::render::{render, RenderOptions};
    use handeye_core::geometry::pose_from_rotvec;
    use nalgebra::Vector3;
    use rand::SeedableRng;

    let out = corpus().join("png");
    std::fs::create_dir_all(&out).unwrap();
    let picture = load_gray_image(&repo().join("configs/targets/board-frame-2x2.png")).unwrap();
    let small = image::imageops::resize(&picture, 200, 131, image::imageops::Triangle);
    small.save(out.join("board-2x2-200px.png")).unwrap();
    let rgb = image::DynamicImage::ImageLuma8(image::imageops::resize(
        &picture,
        120,
        78,
        image::imageops::Triangle,
    ))
    .into_rgb8();
    rgb.save(out.join("board-2x2-rgb-120px.png")).unwrap();

    let board = Board::load(&repo().join("configs/targets/aprilgrid-6x6.yaml")).unwrap();
    let camera = model_for(320, 180);
    let extent = board.extent();
    let centre = nalgebra::center(&extent.min, &extent.max);
    let camera_from_target = pose_from_rotvec(
        Vector3::new(-centre.x, -centre.y, 0.45),
        Vector3::new(0.1, -0.15, 0.05),
    );
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let frame = render(
        &board,
        &camera,
        &camera_from_target,
        &RenderOptions::default(),
        &mut rng,
    );
    frame.save(out.join("sim-frame-320x180.png")).unwrap();

    // Known crashes, kept for the ignored tests below.
    let crashes = corpus().join("crashes");
    std::fs::create_dir_all(&crashes).unwrap();
    GrayImage::from_pixel(1, 1, Luma([128]))
        .save(crashes.join("detector-1x1.png"))
        .unwrap();
    GrayImage::from_pixel(2000, 1, Luma([128]))
        .save(crashes.join("detector-2000x1.png"))
        .unwrap();
}

mod crashes;
