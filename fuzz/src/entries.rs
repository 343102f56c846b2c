// Entry functions of the fuzz targets, shared by the cargo-fuzz crate (`fuzz/src/lib.rs`
// `include!`s this file) and the stable replay test (`tests/fuzz_replay.rs` at the workspace
// root `include!`s it too), so the logic exists once. Each entry takes arbitrary bytes and calls
// only public library APIs; an error is a correct answer, a panic (or a failed assertion of an
// invariant the API documents) is a bug.
//
// Targets: `mcap_ingest`, `cdr`, `ros2msg`, `signal_path`, `model_load`, `step`.

/// The names of the fuzz targets, in the order of [`run_entry`].
pub const TARGETS: [&str; 6] = [
    "mcap_ingest",
    "cdr",
    "ros2msg",
    "signal_path",
    "model_load",
    "step",
];

/// Runs target `name` on `data`; unknown names do nothing.
pub fn run_entry(name: &str, data: &[u8]) {
    match name {
        "mcap_ingest" => mcap_ingest(data),
        "cdr" => cdr(data),
        "ros2msg" => ros2msg(data),
        "signal_path" => signal_path(data),
        "model_load" => model_load(data),
        "step" => step(data),
        _ => {}
    }
}

/// Message paths tried on every log: those of the fixtures, `hbn simulate` and the README.
const MCAP_PATHS: [&str; 14] = [
    "/input.data",
    "/state.data",
    "/sensor.data",
    "/status.ok",
    "/status.count",
    "/vec.v[-1]",
    "/actuator.pressure",
    "/actuator.segments[1].angle",
    "/actuator.segments[-1].counts[2]",
    "/actuator.accel[1]",
    "/actuator.header.stamp.nanosec",
    "/joint_states.position[0]",
    "/joint_states.effort[2]",
    "/hbn/estimate.x",
];

fn scratch_file(ext: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("hbn-fuzz-{}.{ext}", std::process::id()))
}

/// The mcap crate's reader panics on some malformed records (0.26, read.rs: an attachment
/// shorter than its header slices `body[header_len..body.len() - 4]`); hbn-io catches a panic
/// raised while it reads a record and reports the file as corrupt (its test
/// `a_record_that_makes_the_mcap_crate_panic_is_a_corrupt_file`). libFuzzer's panic hook
/// aborts on every panic, caught or not, so this target lets a panic raised *inside the mcap
/// crate* unwind to hbn-io's catch (silently); every other panic still aborts, and an mcap
/// panic that hbn-io does not catch reaches libfuzzer-sys's own catch, which aborts too.
fn tolerate_caught_mcap_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let abort_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let in_mcap = info.location().is_some_and(|l| {
                let f = l.file();
                f.contains("/mcap-") && f.contains("/src/")
            });
            if !in_mcap {
                abort_hook(info);
            }
        }));
    });
}

/// MCAP ingest as `hbn train` / `hbn estimate` do it: list the topics, read the signals of every
/// known path whose topic is present (by log time or header stamps, one per input), resample
/// them onto one grid at a fixed rate and at the first signal's native rate.
pub fn mcap_ingest(data: &[u8]) {
    use hbn_io::{ReadOptions, ResampleOptions, SignalPath, TimeSource};
    tolerate_caught_mcap_panics();
    let file = scratch_file("mcap");
    if std::fs::write(&file, data).is_err() {
        return;
    }
    let topics: Vec<String> = match hbn_io::list_topics(&file) {
        Ok(t) => t.into_iter().map(|t| t.topic).collect(),
        Err(_) => Vec::new(),
    };
    let mut paths: Vec<SignalPath> = MCAP_PATHS
        .iter()
        .filter_map(|p| p.parse::<SignalPath>().ok())
        .filter(|p| topics.contains(&p.topic))
        .collect();
    if paths.is_empty() {
        // Still read: a missing topic must be an error, not a panic.
        paths = MCAP_PATHS[..3]
            .iter()
            .filter_map(|p| p.parse().ok())
            .collect();
    }
    // One clock per input, chosen by the input's length (mutations change it often), so each
    // execution parses the file twice (listing, reading), not three times: the campaign's
    // 10^6 executions of this, the slowest target, then fit in hours, not a day.
    let time_source = if data.len().is_multiple_of(2) {
        TimeSource::LogTime
    } else {
        TimeSource::HeaderStamp
    };
    {
        let opts = ReadOptions { time_source };
        let Ok(signals) = hbn_io::read_signals(&file, &paths, &opts) else {
            let _ = std::fs::remove_file(&file);
            return;
        };
        for s in &signals {
            assert_eq!(s.t_ns.len(), s.value.len());
            assert!(s.t_ns.windows(2).all(|w| w[0] < w[1]), "times increase");
            assert!(s.value.iter().all(|v| v.is_finite()), "values are finite");
        }
        let mut rates = vec![100.0];
        if let Some(r) = signals.first().and_then(hbn_io::native_rate_hz) {
            rates.push(r);
        }
        for rate in rates {
            if let Ok(a) = hbn_io::resample(&signals, &ResampleOptions::new(rate)) {
                assert!(a.columns.iter().all(|c| c.len() == a.t_s.len()));
                assert!(a.columns.iter().flatten().all(|v| v.is_finite()));
            }
        }
    }
    let _ = std::fs::remove_file(&file);
}

/// `ros2msg` schemas for the CDR target: the stamped scalar hbn writes and a message with
/// nested types, fixed, bounded and unbounded arrays, strings and every primitive width.
const CDR_SCHEMAS: [(&str, &str); 2] = [
    (
        "hbn/msg/StampedScalar",
        "std_msgs/Header header\nfloat64 data\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
    ),
    (
        "test_msgs/msg/Mixed",
        "Header header\nstring[] name\nfloat64[] position\nfloat32[3] accel\nint8 mode\nuint16 count\nint64 big\nbool ok\nSegment[<=4] segments\nstring<=5[<=2] tags\nbyte b\nchar c\n================================================================================\nMSG: test_msgs/Segment\nfloat64 angle\nint32[] counts\n",
    ),
];

const CDR_PATHS: [&str; 13] = [
    "data",
    "header.stamp.sec",
    "header.stamp.nanosec",
    "position[0]",
    "position[-1]",
    "accel[2]",
    "mode",
    "count",
    "big",
    "ok",
    "segments[1].angle",
    "segments[-1].counts[2]",
    "name[0]",
];

/// CDR decoding: byte 0 picks the schema, byte 1 the path; the rest is the message.
pub fn cdr(data: &[u8]) {
    let [s, p, msg @ ..] = data else {
        return;
    };
    let (name, text) = CDR_SCHEMAS[usize::from(*s) % CDR_SCHEMAS.len()];
    let Ok(schema) = hbn_io::ros2msg::Ros2Schema::parse(name, text) else {
        panic!("built-in schema {name} must parse");
    };
    let path = CDR_PATHS[usize::from(*p) % CDR_PATHS.len()];
    let Ok(sp) = format!("/t.{path}").parse::<hbn_io::SignalPath>() else {
        panic!("built-in path {path} must parse");
    };
    if let Ok(v) = hbn_io::decode_cdr_field(&schema, msg, "/t", &sp.fields) {
        assert!(v.is_finite() || v.is_nan() || v.is_infinite());
    }
}

/// `ros2msg` schema parsing: the text up to the first NUL byte is the schema (byte 0 picks
/// the type name); after it, a CDR message decoded at every root field.
pub fn ros2msg(data: &[u8]) {
    let [sel, rest @ ..] = data else {
        return;
    };
    let (text, msg) = match rest.iter().position(|b| *b == 0) {
        Some(i) => (&rest[..i], &rest[i + 1..]),
        None => (rest, &[][..]),
    };
    let text = String::from_utf8_lossy(text);
    let name = ["pkg/msg/T", "pkg/T", "T", "a/b/c/d", ""][usize::from(*sel) % 5];
    let Ok(schema) = hbn_io::ros2msg::Ros2Schema::parse(name, &text) else {
        return;
    };
    assert!(schema.root < schema.types.len());
    let Some(root) = schema.root_type() else {
        return;
    };
    for f in root.fields.iter().take(16) {
        for path in [
            vec![hbn_io::PathElem::Field(f.name.clone())],
            vec![
                hbn_io::PathElem::Field(f.name.clone()),
                hbn_io::PathElem::Index(-1),
            ],
        ] {
            let _ = hbn_io::decode_cdr_field(&schema, msg, "/t", &path);
        }
    }
}

/// Foxglove message paths: parsing, and printing then parsing again gives the same path.
pub fn signal_path(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(p) = text.parse::<hbn_io::SignalPath>() {
        let printed = p.to_string();
        let again: hbn_io::SignalPath = match printed.parse() {
            Ok(q) => q,
            Err(e) => panic!("{text:?} printed as {printed:?} does not parse: {e}"),
        };
        assert_eq!(p, again, "{text:?} -> {printed:?}");
        let _ = p.field_string();
    }
}

/// Model file loading (`hbn estimate --model`, `HysteresisModel::load`): parse; if the model loads,
/// build its view and run every estimator mode for a few steps.
pub fn model_load(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let _ = hbn_gp::GaussianProcess::from_json(text, "fuzz.gp");
    let Ok(model) = hbn_model::HysteresisModel::from_json(text, "fuzz.hbn") else {
        return;
    };
    let u: Vec<f64> = (0..20).map(|k| 0.05 * k as f64).collect();
    for mode in hbn_core::Mode::ALL {
        if let Ok(est) = model.estimate(&u, &u, mode) {
            assert!(est.x.iter().all(|v| v.is_finite()), "estimate is finite");
        }
    }
}

/// Reads `f64`s and small integers from fuzz bytes; zeros when exhausted.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn byte(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }
    /// Any `f64` bit pattern (NaN, infinities, huge, subnormal), or a tamer value, by tag.
    fn f64(&mut self) -> f64 {
        let tag = self.byte();
        match tag % 4 {
            0 => {
                let mut b = [0u8; 8];
                for x in &mut b {
                    *x = self.byte();
                }
                f64::from_le_bytes(b)
            }
            1 => f64::from(self.byte() as i8) / 16.0,
            2 => [f64::NAN, f64::INFINITY, -f64::INFINITY, 1e308, -1e308, 1e-310, 0.0, -0.0]
                [usize::from(self.byte() % 8)],
            _ => f64::from(self.byte()) / 255.0,
        }
    }
    fn vec(&mut self, n: usize) -> Vec<f64> {
        (0..n).map(|_| self.f64()).collect()
    }
}

/// The estimator step on a model view built from arbitrary slices (rejected views are fine),
/// with arbitrary `u`, `y`: every output must be finite.
pub fn step(data: &[u8]) {
    use hbn_core::blr::{LocalRegression, Neighbourhood, NeighbourhoodParts};
    use hbn_core::gp::{GpParts, GpView, Variance};
    use hbn_core::kernel::{Kernel, KernelSpec, Metric, Profile};
    use hbn_core::{EkfConfig, Estimator, HbnView, InitPrior, Mode, Plays};

    let mut b = Bytes(data);
    struct Owned {
        spec: KernelSpec,
        theta: Vec<f64>,
        whiten: Vec<f64>,
        mean: Vec<f64>,
        scale: Vec<f64>,
        feats: Vec<f64>,
        dirs: Vec<f64>,
        alpha: Vec<f64>,
        f1: Vec<f64>,
        out: [f64; 3],
        sparse: bool,
    }
    fn gp(b: &mut Bytes<'_>, d: usize) -> Owned {
        let flags = b.byte();
        let n = 1 + usize::from(b.byte() % 6);
        let spec = KernelSpec {
            profile: if flags & 1 == 0 {
                Profile::SquaredExponential
            } else {
                Profile::Matern52
            },
            metric: [Metric::Isotropic, Metric::Ard, Metric::Mahalanobis][usize::from(flags >> 1) % 3],
            dim: d,
            warp_units: usize::from((flags >> 3) % 3),
            direction: if flags & 32 != 0 { Some([d - 1, 0]) } else { None },
        };
        let tri = n * (n + 1) / 2;
        Owned {
            theta: b.vec(spec.n_params()),
            whiten: b.vec(d * d),
            mean: b.vec(d),
            scale: b.vec(d),
            feats: b.vec(n * d),
            dirs: b.vec(n),
            alpha: b.vec(n),
            f1: b.vec(tri),
            // The byte layout has room for a second factor, which no view has; its bytes are
            // consumed and ignored so that the committed corpora keep their meaning.
            out: {
                let _second_factor = b.vec(tri);
                [b.f64(), b.f64(), b.f64()]
            },
            sparse: flags & 64 != 0,
            spec,
        }
    }
    let tr = gp(&mut b, 4);
    let se = gp(&mut b, 3);
    fn view(o: &Owned) -> Option<GpView<'_>> {
        let kernel = Kernel::new(o.spec, &o.theta, &o.whiten).ok()?;
        GpView::new(GpParts {
            kernel,
            input_mean: &o.mean,
            input_scale: &o.scale,
            output_mean: o.out[0],
            output_scale: o.out[1],
            linear: &[],
            features: &o.feats,
            directions: if o.spec.direction.is_some() { &o.dirs } else { &[] },
            alpha: &o.alpha,
            alpha_lo: &o.alpha,
            variance: if o.sparse {
                Variance::Sparse {
                    variance_factor: &o.f1,
                }
            } else {
                Variance::Exact { chol_packed: &o.f1 }
            },
            noise_var: o.out[2],
        })
        .ok()
    }
    // Local regression data: one cell with up to 60 samples around the origin.
    type Local = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, usize);
    fn local(b: &mut Bytes<'_>, d: usize) -> Local {
        let n = usize::from(b.byte() % 60);
        (b.vec(n * d), b.vec(n), b.vec(d), b.vec(d), n)
    }
    let tl = local(&mut b, 4);
    let sl = local(&mut b, 3);
    fn nb<'a>(l: &'a Local, d: usize, start: &'static [u32; 2]) -> Option<Neighbourhood<'a>> {
        Neighbourhood::new(
            d,
            NeighbourhoodParts {
                inputs: &l.0,
                targets: &l.1,
                cell_keys: &[0],
                cell_start: start,
                origin: &[-1e3; 4][..d],
                half_window: &l.2,
                input_var: &l.3,
            },
        )
        .ok()
    }
    static STARTS: [[u32; 2]; 61] = {
        let mut s = [[0u32; 2]; 61];
        let mut i = 0;
        while i < 61 {
            s[i] = [0, i as u32];
            i += 1;
        }
        s
    };
    let blr = LocalRegression {
        nu0: b.f64(),
        kappa: b.f64(),
        max_neighbours: usize::from(b.byte()),
    };
    let cfg = |b: &mut Bytes<'_>, mode: Mode| EkfConfig {
        mode,
        q_floor: b.f64(),
        r_floor: b.f64(),
        qx_model_floor: b.f64(),
        r_model_floor: b.f64(),
        p_min: b.f64(),
        p_max: b.f64(),
        jac_max: b.f64(),
        innovation_min: b.f64(),
        nis_gate: b.f64(),
        x_bounds: (b.f64(), b.f64()),
        y_bounds: (b.f64(), b.f64()),
        x0_mean: b.f64(),
        x0_var: b.f64(),
        q_scale: b.f64(),
        r_scale: b.f64(),
        std_scale: b.f64(),
    };
    // Every mode: EKF, EKF+BLR and UKF.
    let mode = Mode::ALL[usize::from(b.byte()) % Mode::ALL.len()];
    let config = cfg(&mut b, mode);
    let (Some(transition), Some(sensor)) = (view(&tr), view(&se)) else {
        return;
    };
    // The prior of x_0 from the first measurement: arbitrary (y, x) pairs, sorted by y.
    let mut pairs: Vec<[f64; 2]> = (0..b.byte() % 8).map(|_| [b.f64(), b.f64()]).collect();
    pairs.sort_by(|a, c| a[0].total_cmp(&c[0]));
    let init = InitPrior::new(&pairs, 1 + usize::from(b.byte() % 4), b.f64().abs()).ok();
    let model = HbnView {
        transition,
        sensor,
        transition_local: nb(&tl, 4, &STARTS[tl.4]),
        sensor_local: nb(&sl, 3, &STARTS[sl.4]),
        blr,
        init,
        // The byte layout has no play operators (so that the committed corpora keep their
        // meaning); the step advances the plays with or without them.
        plays: Plays::NONE,
        sensor_memory: Plays::NONE,
    };
    // The same model read as a sensor with memory of the state (when its sensor GP has the
    // three inputs that takes), stepped beside it on the same samples: no bytes of its own.
    let memory = Plays::new(&[0.05, 0.3]).ok();
    let with_memory = memory.map(|sensor_memory| HbnView {
        sensor_memory,
        ..model
    });
    let mut scratch = vec![0.0; Estimator::scratch_len(&model)];
    let mut memory_scratch = vec![0.0; Estimator::scratch_len(&model)];
    let Ok(mut est) = Estimator::new(model, config, &mut scratch) else {
        return;
    };
    let mut est_memory =
        with_memory.and_then(|m| Estimator::new(m, config, &mut memory_scratch).ok());
    for _ in 0..64 {
        let (u, y) = (b.f64(), b.f64());
        let outs = [Some(est.step(u, y)), est_memory.as_mut().map(|e| e.step(u, y))];
        for out in outs.into_iter().flatten() {
            assert!(
                out.x.is_finite()
                    && out.x_std.is_finite()
                    && out.y_pred.is_finite()
                    && out.innovation_var.is_finite()
                    && out.q_x.is_finite()
                    && out.r.is_finite()
                    && out.jacobian.iter().all(|v| v.is_finite()),
                "non-finite step output {out:?} (u {u}, y {y})"
            );
        }
        if b.0.is_empty() {
            break;
        }
    }
}
