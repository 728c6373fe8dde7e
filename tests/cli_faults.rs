//! Promises that hold under faults (issue 14), through the `cpm` binary: outputs never replace
//! a device, FIFO, link target that is not a regular file, or an input of the run; a closed or
//! full standard output is an I/O error; a result directory is committed as one step, so a
//! process killed at any step of the commit (the test hook `CPM_FAULT_AT`) leaves exactly one
//! complete result (the previous or the new one), the next run cleans up, and concurrent runs
//! on one `--out` end with one complete result.
use std::collections::BTreeMap;
use std::os::unix::fs::FileTypeExt as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn example(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(name)
        .display()
        .to_string()
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("faults-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn cmd(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_cpm"));
    c.args(args);
    c
}

fn cpm(args: &[&str]) -> Output {
    cmd(args).output().expect("run cpm")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn p(path: &Path) -> &str {
    path.to_str().unwrap()
}

fn export(out: &Path) -> Output {
    cpm(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &example("hexapod_66.toml"),
        "--out",
        p(out),
    ])
}

fn assert_refused(o: &Output, what: &str) {
    assert_eq!(o.status.code(), Some(2), "{what}: {}", stderr(o));
    assert!(stderr(o).contains("--out"), "{what}: {}", stderr(o));
}

#[test]
fn a_fifo_a_device_and_links_to_them_are_never_replaced() {
    let d = scratch("nodes");
    let fifo = d.join("fifo");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let o = export(&fifo);
    assert_refused(&o, "fifo");
    assert!(stderr(&o).contains("not a regular file"), "{}", stderr(&o));
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());

    // /dev/null: refused, and still a character device afterwards (also when run as root).
    let o = export(Path::new("/dev/null"));
    assert_refused(&o, "/dev/null");
    assert!(std::fs::symlink_metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());

    // A link to a device: refused, the link and the device stay.
    let link = d.join("null-link");
    std::os::unix::fs::symlink("/dev/null", &link).unwrap();
    assert_refused(&export(&link), "link to /dev/null");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::symlink_metadata("/dev/null")
        .unwrap()
        .file_type()
        .is_char_device());

    // A dangling link: refused, left as it is.
    let dangling = d.join("dangling");
    std::os::unix::fs::symlink(d.join("nowhere.hal"), &dangling).unwrap();
    assert_refused(&export(&dangling), "dangling link");
    assert!(!d.join("nowhere.hal").exists());
    assert!(std::fs::symlink_metadata(&dangling)
        .unwrap()
        .file_type()
        .is_symlink());

    // A link to a regular file is written through: the link stays, its target changes.
    let target = d.join("joints.hal");
    std::fs::write(&target, "old").unwrap();
    let link = d.join("joints-link.hal");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let o = export(&link);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read_to_string(&target)
        .unwrap()
        .contains("setp genhexkins.base.0.x"));

    // A directory result at a FIFO: refused.
    let o = cpm(&[
        "design",
        "--robot",
        &example("hexapod_66.toml"),
        "--readings",
        "60",
        "--out",
        p(&fifo),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());
}

#[test]
fn dash_writes_single_file_outputs_to_standard_output() {
    let o = cpm(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &example("hexapod_66.toml"),
        "--out",
        "-",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("setp genhexkins.platform.5.z"), "{text}");
    assert!(!text.contains("wrote"), "{text}");
    assert!(!Path::new("-").exists());

    // simulate --out - writes what simulate --out FILE writes.
    let d = scratch("dash");
    let sim = |out: &str| {
        cpm(&[
            "simulate",
            "--robot",
            &example("hexapod_66.toml"),
            "--random",
            "5",
            "--out",
            out,
        ])
    };
    let o = sim("-");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let file = d.join("d.csv");
    let f = sim(p(&file));
    assert_eq!(f.status.code(), Some(0), "{}", stderr(&f));
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.starts_with("# simulated by cpm"), "{text}");
    let data = |t: &str| -> Vec<String> {
        t.lines()
            .filter(|l| !l.starts_with('#'))
            .map(str::to_string)
            .collect()
    };
    let from_file = std::fs::read_to_string(&file).unwrap();
    assert!(data(&text).len() > 5, "{text}");
    assert_eq!(data(&text), data(&from_file));
}

#[test]
fn an_output_that_is_an_input_is_refused() {
    let d = scratch("same");
    let robot = d.join("robot.toml");
    std::fs::copy(example("hexapod_66.toml"), &robot).unwrap();
    let before = std::fs::read(&robot).unwrap();
    let r = p(&robot);
    // export --out robot.toml, also through a link and a hard link.
    assert_refused(&export_from(r, r), "export over its robot");
    let alias = d.join("alias.toml");
    std::os::unix::fs::symlink(&robot, &alias).unwrap();
    assert_refused(
        &export_from(r, p(&alias)),
        "export over a link to its robot",
    );
    let hard = d.join("hard.toml");
    std::fs::hard_link(&robot, &hard).unwrap();
    assert_refused(
        &export_from(r, p(&hard)),
        "export over a hard link to its robot",
    );
    // simulate --out robot.toml
    let o = cpm(&["simulate", "--robot", r, "--random", "5", "--out", r]);
    assert_refused(&o, "simulate over its robot");
    assert!(stderr(&o).contains("is the input"), "{}", stderr(&o));
    assert_eq!(std::fs::read(&robot).unwrap(), before);

    // compensate --poses t.csv --out t.csv
    let targets = d.join("t.csv");
    std::fs::write(
        &targets,
        "x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg\n0,0,0,0,0,0\n",
    )
    .unwrap();
    let t_before = std::fs::read(&targets).unwrap();
    let o = cpm(&[
        "compensate",
        "--robot",
        r,
        "--poses",
        p(&targets),
        "--out",
        p(&targets),
    ]);
    assert_refused(&o, "compensate over its targets");
    assert_eq!(std::fs::read(&targets).unwrap(), t_before);

    // calibrate --robot cal/calibrated.toml --out cal: the result would replace its robot.
    let data = d.join("data.csv");
    let o = cpm(&[
        "simulate",
        "--robot",
        r,
        "--random",
        "30",
        "--noise",
        "gaussian:0.5",
        "--out",
        p(&data),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let cal = d.join("cal");
    let o = cpm(&[
        "calibrate",
        "--robot",
        r,
        "--data",
        p(&data),
        "--out",
        p(&cal),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let snap = snapshot(&cal);
    let o = cpm(&[
        "calibrate",
        "--robot",
        p(&cal.join("calibrated.toml")),
        "--data",
        p(&data),
        "--out",
        p(&cal),
    ]);
    assert_refused(&o, "calibrate over its robot");
    assert_eq!(snapshot(&cal), snap);
}

fn export_from(robot: &str, out: &str) -> Output {
    cpm(&[
        "export", "--format", "linuxcnc", "--robot", robot, "--out", out,
    ])
}

#[test]
fn a_closed_or_full_standard_output_is_an_io_error() {
    // `cpm export ... >&-`
    assert_stdout_closed(&export_in_shell(">&-"));
    // ... > /dev/full
    let full = std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .unwrap();
    let o = cmd(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &example("hexapod_66.toml"),
    ])
    .stdout(Stdio::from(full))
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(4), "{}", stderr(&o));
    // ... > /dev/null is fine.
    let o = cmd(&[
        "export",
        "--format",
        "linuxcnc",
        "--robot",
        &example("hexapod_66.toml"),
    ])
    .stdout(Stdio::null())
    .output()
    .unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn stdout_on_dev_null_opened_read_write_is_not_closed() {
    // Python's `subprocess.DEVNULL` opens /dev/null O_RDWR, as the Rust runtime does on a
    // closed descriptor 1; it was refused as closed (exit 4).
    let export = |stdout: Stdio| {
        cmd(&[
            "export",
            "--format",
            "linuxcnc",
            "--robot",
            &example("hexapod_66.toml"),
        ])
        .stdout(stdout)
        .output()
        .unwrap()
    };
    let dev_null = || {
        std::fs::File::options()
            .read(true)
            .write(true)
            .open("/dev/null")
            .unwrap()
    };
    let o = export(Stdio::from(dev_null()));
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(stderr(&o).is_empty(), "{}", stderr(&o));
    // The same through a shell (`1<>/dev/null`), and with stdin and stderr closed too.
    let o = export_in_shell("1<>/dev/null <&-");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // A closed stdout is still refused when stdin is closed as well.
    assert_stdout_closed(&export_in_shell(">&- <&-"));
}

/// `cpm export` of the hexapod example run by `sh` with `redirections`.
fn export_in_shell(redirections: &str) -> Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "exec \"$0\" export --format linuxcnc --robot \"$1\" {redirections}"
        ))
        .arg(env!("CARGO_BIN_EXE_cpm"))
        .arg(example("hexapod_66.toml"))
        .output()
        .unwrap()
}

fn assert_stdout_closed(o: &Output) {
    assert_eq!(o.status.code(), Some(4), "{}", stderr(o));
    assert!(
        stderr(o).contains("standard output is closed"),
        "{}",
        stderr(o)
    );
}

// ---------------------------------------------------------------------------------------
// Result directories: all or nothing under faults and concurrency.

const MANIFEST: &str = ".cpm-result.json";

/// Every file under `dir` (recursively), relative, with its contents.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let q = e.unwrap().path();
            if q.is_dir() {
                stack.push(q);
            } else {
                out.insert(
                    q.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&q).unwrap(),
                );
            }
        }
    }
    out
}

fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Checks that `dir` holds exactly one complete result: its manifest lists every file
/// present (besides the user's `notes.txt`) with the fingerprint it has, and the result is
/// the calibration of one of `references` (its `calibrated.toml`). Returns which reference.
fn complete_result(dir: &Path, references: &[&[u8]]) -> Result<usize, String> {
    let snap = snapshot(dir);
    let manifest: serde_json::Value = serde_json::from_slice(
        snap.get(Path::new(MANIFEST))
            .ok_or_else(|| format!("{}: no manifest; files {:?}", dir.display(), snap.keys()))?,
    )
    .map_err(|e| e.to_string())?;
    let listed = manifest["files"].as_array().ok_or("no file list")?;
    let mut names: Vec<PathBuf> = vec![PathBuf::from(MANIFEST), PathBuf::from("notes.txt")];
    for f in listed {
        let name = PathBuf::from(f["name"].as_str().unwrap());
        let bytes = snap
            .get(&name)
            .ok_or_else(|| format!("{} listed but missing", name.display()))?;
        let want = f["fnv1a64"].as_str().unwrap();
        if format!("{:016x}", fnv1a64(bytes)) != want {
            return Err(format!("{} is not the file of this run", name.display()));
        }
        names.push(name);
    }
    names.sort();
    let present: Vec<PathBuf> = snap.keys().cloned().collect();
    if present != names {
        return Err(format!("files {present:?}, manifest and notes {names:?}"));
    }
    if snap[Path::new("notes.txt")] != b"the operator's notes" {
        return Err("notes.txt changed".into());
    }
    let toml = &snap[Path::new("calibrated.toml")];
    references
        .iter()
        .position(|r| r == toml)
        .ok_or_else(|| "calibrated.toml is from neither run".into())
}

/// cpm's hidden siblings of `dir` other than the lock.
fn leftovers(dir: &Path) -> Vec<String> {
    let name = dir.file_name().unwrap().to_string_lossy().into_owned();
    std::fs::read_dir(dir.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&format!(".{name}.")) && !n.ends_with(".cpm-lock"))
        .collect()
}

struct Campaigns {
    dir: PathBuf,
    data: [PathBuf; 2],
    reference: [Vec<u8>; 2],
}

fn campaigns(name: &str) -> Campaigns {
    let dir = scratch(name);
    let robot = example("hexapod_66.toml");
    let data = [dir.join("d1.csv"), dir.join("d2.csv")];
    let mut reference = [Vec::new(), Vec::new()];
    for (k, seed) in ["1", "2"].iter().enumerate() {
        let o = cpm(&[
            "simulate",
            "--robot",
            &robot,
            "--random",
            "30",
            "--noise",
            "gaussian:0.5",
            "--seed",
            seed,
            "--out",
            p(&data[k]),
        ]);
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        let out = dir.join(format!("ref{k}"));
        let o = calibrate(&data[k], &out).output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        reference[k] = std::fs::read(out.join("calibrated.toml")).unwrap();
    }
    assert_ne!(reference[0], reference[1]);
    Campaigns {
        dir,
        data,
        reference,
    }
}

fn calibrate(data: &Path, out: &Path) -> Command {
    cmd(&[
        "calibrate",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        p(data),
        "--out",
        p(out),
    ])
}

#[test]
fn a_commit_killed_at_any_step_leaves_one_complete_result() {
    let c = campaigns("kill");
    let refs: [&[u8]; 2] = [&c.reference[0], &c.reference[1]];
    let mut outcomes = Vec::new();
    for no_exchange in ["0", "1"] {
        for step in cpm::output::COMMIT_STEPS {
            let out = c.dir.join(format!("cal-{step}-{no_exchange}"));
            // The previous result: campaign 1, with a file of the operator's beside it.
            let o = calibrate(&c.data[0], &out).output().unwrap();
            assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
            std::fs::write(out.join("notes.txt"), "the operator's notes").unwrap();
            assert_eq!(complete_result(&out, &refs), Ok(0));
            let before = snapshot(&out);
            // The new run, killed at `step`.
            let o = calibrate(&c.data[1], &out)
                .env("CPM_FAULT_AT", step)
                .env("CPM_FAULT_NO_EXCHANGE", no_exchange)
                .output()
                .unwrap();
            let killed = o.status.code().is_none();
            let reached = !(no_exchange == "0" && *step == "moved-aside");
            assert_eq!(killed, reached, "{step}: {}", stderr(&o));
            let state = if !out.exists() {
                // Only between the two renames of the fallback: the previous result is aside.
                assert_eq!((no_exchange, *step), ("1", "moved-aside"));
                assert!(leftovers(&out).iter().any(|n| n.contains(".cpm-old-")));
                "moved aside".to_string()
            } else {
                let which = complete_result(&out, &refs)
                    .unwrap_or_else(|e| panic!("{step} (fallback {no_exchange}): {e}"));
                if which == 0 {
                    assert_eq!(
                        snapshot(&out),
                        before,
                        "{step}: the previous result changed"
                    );
                }
                ["previous", "new"][which].to_string()
            };
            let left = leftovers(&out);
            // The next run cleans up (or puts the previous result back) and commits.
            let o = calibrate(&c.data[1], &out).output().unwrap();
            assert_eq!(o.status.code(), Some(0), "{step}: {}", stderr(&o));
            if !left.is_empty() {
                assert!(
                    stderr(&o).contains("interrupted"),
                    "{step}: {left:?} {}",
                    stderr(&o)
                );
            }
            assert_eq!(leftovers(&out), Vec::<String>::new(), "{step}");
            assert_eq!(complete_result(&out, &refs), Ok(1), "{step}");
            outcomes.push(format!(
                "{step}{}: {state}, {} leftover(s)",
                if no_exchange == "1" {
                    " (two renames)"
                } else {
                    ""
                },
                left.len()
            ));
        }
    }
    println!("fault injection:\n  {}", outcomes.join("\n  "));
}

#[test]
fn concurrent_runs_on_one_directory_end_with_one_complete_result() {
    let c = campaigns("concurrent");
    let refs: [&[u8]; 2] = [&c.reference[0], &c.reference[1]];
    let out = c.dir.join("cal");
    let o = calibrate(&c.data[0], &out).output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    std::fs::write(out.join("notes.txt"), "the operator's notes").unwrap();
    let mut seen = [0usize; 2];
    for round in 0..3 {
        let children: Vec<_> = (0..4)
            .map(|k| {
                calibrate(&c.data[(k + round) % 2], &out)
                    .stdout(Stdio::null())
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for ch in children {
            let o = ch.wait_with_output().unwrap();
            assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
        }
        let which = complete_result(&out, &refs).unwrap_or_else(|e| panic!("round {round}: {e}"));
        seen[which] += 1;
        assert_eq!(leftovers(&out), Vec::<String>::new());
    }
    println!("concurrent rounds ending with campaign 1 / campaign 2: {seen:?}");
}

// ---------------------------------------------------------------------------------------
// Robust fits and refine.

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn hexapod_campaign(d: &Path) -> PathBuf {
    let data = d.join("data.csv");
    let o = cpm(&[
        "simulate",
        "--robot",
        &example("hexapod_66.toml"),
        "--random",
        "40",
        "--noise",
        "gaussian:0.5",
        "--out",
        p(&data),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    data
}

fn calibrate_robust(data: &Path, out: &Path, robust: Option<&str>) -> Output {
    let mut args = vec![
        "calibrate".to_string(),
        "--robot".into(),
        example("hexapod_66.toml"),
        "--data".into(),
        p(data).into(),
        "--out".into(),
        p(out).into(),
    ];
    if let Some(r) = robust {
        args.extend(["--robust".to_string(), r.to_string()]);
    }
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    cpm(&args)
}

#[test]
fn a_robust_fit_on_clean_data_matches_least_squares_and_one_that_ignores_the_data_fails() {
    let d = scratch("robust");
    let data = hexapod_campaign(&d);
    let o = calibrate_robust(&data, &d.join("ls"), None);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let ls = read_json(&d.join("ls/calibration.json"));
    let ls_rms = ls["residual_rms_um"].as_f64().unwrap();
    for loss in ["tukey:3", "cauchy:3", "huber:1.5", "tukey:1.5"] {
        let out = d.join(loss.replace(':', "-"));
        let o = calibrate_robust(&data, &out, Some(loss));
        assert_eq!(o.status.code(), Some(0), "{loss}: {}", stderr(&o));
        let v = read_json(&out.join("calibration.json"));
        let rms = v["residual_rms_um"].as_f64().unwrap();
        assert!(
            rms < 1.2 * ls_rms,
            "{loss}: residual {rms} um against {ls_rms} um for least squares"
        );
        let share = v["robust"]["downweighted_share"].as_f64().unwrap();
        assert!(share < 0.3, "{loss}: {share}");
        assert_eq!(v["robust"]["failed"], false);
    }
    // K far below the noise: most observations down-weighted: failed, exit 1, outputs say so.
    let out = d.join("tiny");
    let o = calibrate_robust(&data, &out, Some("tukey:0.01"));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("ignored most of the data"),
        "{}",
        stderr(&o)
    );
    let v = read_json(&out.join("calibration.json"));
    assert_eq!(v["robust"]["failed"], true);
    assert!(v["robust"]["downweighted_share"].as_f64().unwrap() > 0.5);
    assert!(std::fs::read_to_string(out.join("report.md"))
        .unwrap()
        .contains("The fit failed"));
}

#[test]
fn refine_adds_no_effect_for_a_spike_and_flags_it() {
    let d = scratch("spike");
    let data = hexapod_campaign(&d);
    // One 5 mm spike on the 91st reading.
    let text = std::fs::read_to_string(&data).unwrap();
    let mut k = 0;
    let mut spiked_line = 0;
    let lines: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(n, l)| {
            if l.starts_with('#') || l.starts_with("pose") {
                return l.to_string();
            }
            k += 1;
            if k != 91 {
                return l.to_string();
            }
            spiked_line = n + 1;
            let mut f: Vec<String> = l.split(',').map(str::to_string).collect();
            f[8] = (f[8].parse::<f64>().unwrap() + 5.0).to_string();
            f.join(",")
        })
        .collect();
    let spiked = d.join("spiked.csv");
    std::fs::write(&spiked, lines.join("\n") + "\n").unwrap();
    let out = d.join("refined");
    let o = cpm(&[
        "refine",
        "--robot",
        &example("hexapod_66.toml"),
        "--data",
        p(&spiked),
        "--out",
        p(&out),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let r = read_json(&out.join("refine.json"));
    assert_eq!(r["steps"].as_array().unwrap().len(), 0, "{r:#}");
    assert!(r["outliers_before"].as_u64().unwrap() >= 1);
    for rej in r["rejected_by_cross_validation"].as_array().unwrap() {
        assert!(rej["cv_rms_with_um"].as_f64() >= rej["cv_rms_before_um"].as_f64());
    }
    // Judged against plain calibration on the whole file, the spike included: nothing added,
    // so the same blocked error.
    let against = &r["against_calibrate"];
    let (calibrate, refined) = (
        against["calibrate_cv_rms_um"].as_f64().unwrap(),
        against["refined_cv_rms_um"].as_f64().unwrap(),
    );
    assert!(calibrate > 0.0 && refined == calibrate, "{against}");
    let cal = read_json(&out.join("calibration.json"));
    let flagged = cal["outliers"].to_string();
    assert!(
        flagged.contains(&format!("\"line\":{spiked_line}")),
        "line {spiked_line} not flagged: {flagged}"
    );
}
