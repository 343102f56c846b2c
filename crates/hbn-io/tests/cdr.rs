//! ros2msg schema parsing and CDR decoding on hand-built buffers.
use hbn_io::ros2msg::{ArrayKind, FieldType, Prim, Ros2Schema};
use hbn_io::{IoError, PathElem, decode_cdr_field, stamped_scalar_cdr, stamped_scalar_ros2msg};

/// Minimal CDR writer for tests: alignment relative to the byte after the 4-byte header.
struct W {
    b: Vec<u8>,
    le: bool,
}
impl W {
    fn new(le: bool) -> W {
        W {
            b: vec![0, if le { 1 } else { 0 }, 0, 0],
            le,
        }
    }
    fn align(&mut self, n: usize) {
        while !(self.b.len() - 4).is_multiple_of(n) {
            self.b.push(0xEE); // padding bytes must be ignored whatever they hold
        }
    }
    fn raw(&mut self, mut bytes: Vec<u8>) {
        self.align(bytes.len());
        if !self.le {
            bytes.reverse();
        }
        self.b.extend(bytes);
    }
    fn u8(&mut self, v: u8) {
        self.b.push(v);
    }
    fn i16(&mut self, v: i16) {
        self.raw(v.to_le_bytes().to_vec())
    }
    fn u32(&mut self, v: u32) {
        self.raw(v.to_le_bytes().to_vec())
    }
    fn i32(&mut self, v: i32) {
        self.raw(v.to_le_bytes().to_vec())
    }
    fn f32(&mut self, v: f32) {
        self.raw(v.to_le_bytes().to_vec())
    }
    fn f64(&mut self, v: f64) {
        self.raw(v.to_le_bytes().to_vec())
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.b.extend(s.as_bytes());
        self.b.push(0);
    }
}

fn p(s: &str) -> Vec<PathElem> {
    let sp: hbn_io::SignalPath = format!("/t.{s}").parse().unwrap();
    sp.fields
}

fn get(schema: &Ros2Schema, data: &[u8], path: &str) -> Result<f64, IoError> {
    decode_cdr_field(schema, data, "/t", &p(path))
}

#[test]
fn explicit_le_bytes_with_padding() {
    let s = Ros2Schema::parse("pkg/msg/A", "uint8 a\nfloat64 b\nstring s\nint16 c\n").unwrap();
    #[rustfmt::skip]
    let mut data = vec![
        0x00, 0x01, 0x00, 0x00,         // CDR_LE
        7,    0, 0, 0, 0, 0, 0, 0,      // a, then padding to 8
    ];
    data.extend(2.5f64.to_le_bytes()); // b at offset 8
    data.extend(3u32.to_le_bytes()); // s length incl. NUL, offset 16
    data.extend(b"hi\0"); // offset 20..23
    data.push(0); // pad to 24
    data.extend((-5i16).to_le_bytes());
    assert_eq!(get(&s, &data, "a").unwrap(), 7.0);
    assert_eq!(get(&s, &data, "b").unwrap(), 2.5);
    assert_eq!(get(&s, &data, "c").unwrap(), -5.0);
    match get(&s, &data, "s") {
        Err(IoError::NonNumeric { found, .. }) => assert!(found.contains("\"hi\""), "{found}"),
        other => panic!("{other:?}"),
    }
    // Truncated: error, no panic.
    for n in 0..data.len() - 1 {
        assert!(get(&s, &data[..n], "c").is_err());
    }
}

#[test]
fn big_and_little_endian_agree() {
    let s = Ros2Schema::parse(
        "pkg/msg/B",
        "uint8 a\nfloat64 b\nint32 i\nstring name\nfloat32 f\nint16 c\nfloat64 d\n",
    )
    .unwrap();
    for le in [true, false] {
        let mut w = W::new(le);
        w.u8(1);
        w.f64(-1.25);
        w.i32(-123456);
        w.string("abc");
        w.f32(0.5);
        w.i16(300);
        w.f64(6.0e10);
        let d = &w.b;
        assert_eq!(get(&s, d, "a").unwrap(), 1.0);
        assert_eq!(get(&s, d, "b").unwrap(), -1.25);
        assert_eq!(get(&s, d, "i").unwrap(), -123456.0);
        assert_eq!(get(&s, d, "f").unwrap(), 0.5);
        assert_eq!(get(&s, d, "c").unwrap(), 300.0);
        assert_eq!(get(&s, d, "d").unwrap(), 6.0e10, "le={le}");
    }
}

const OUTER: &str = "# outer\n\
uint8 flag\n\
Inner[] items\n\
Inner[2] fixed\n\
float32[<=3] bounded\n\
bool ok\n\
float64 tail\n\
================================================================================\n\
MSG: pkg/Inner\n\
string<=8 name\n\
float64 v\n\
int32[] xs\n";

fn outer_msg(le: bool) -> Vec<u8> {
    let mut w = W::new(le);
    w.u8(9);
    w.u32(3); // items
    for k in 0..3 {
        w.string(&format!("item{k}"));
        w.f64(k as f64 + 0.5);
        w.u32(k as u32 + 1);
        for j in 0..=k {
            w.i32(100 * k + j);
        }
    }
    for k in 0..2 {
        // fixed: no length prefix
        w.string("f");
        w.f64(-(k as f64));
        w.u32(0);
    }
    w.u32(3);
    w.f32(1.0);
    w.f32(2.0);
    w.f32(3.5);
    w.u8(1);
    w.f64(42.0);
    w.b
}

#[test]
fn arrays_of_nested_structs_and_bounded_arrays() {
    let s = Ros2Schema::parse("pkg/msg/Outer", OUTER).unwrap();
    for le in [true, false] {
        let d = outer_msg(le);
        assert_eq!(get(&s, &d, "flag").unwrap(), 9.0);
        assert_eq!(get(&s, &d, "items[0].v").unwrap(), 0.5);
        assert_eq!(get(&s, &d, "items[1].v").unwrap(), 1.5);
        assert_eq!(get(&s, &d, "items[-1].xs[2]").unwrap(), 202.0);
        assert_eq!(get(&s, &d, "items[2].xs[-3]").unwrap(), 200.0);
        assert_eq!(get(&s, &d, "fixed[1].v").unwrap(), -1.0);
        assert_eq!(get(&s, &d, "bounded[2]").unwrap(), 3.5);
        assert_eq!(get(&s, &d, "ok").unwrap(), 1.0);
        assert_eq!(get(&s, &d, "tail").unwrap(), 42.0, "le={le}");
        // errors
        match get(&s, &d, "items[3].v") {
            Err(IoError::MissingField {
                available, missing, ..
            }) => {
                assert!(available[0].contains("[0]..[2]"), "{available:?}");
                assert!(missing.contains("items[3]"), "{missing}");
            }
            other => panic!("{other:?}"),
        }
        match get(&s, &d, "items[0].nope") {
            Err(IoError::MissingField { available, .. }) => {
                assert_eq!(available, vec!["name", "v", "xs"])
            }
            other => panic!("{other:?}"),
        }
        match get(&s, &d, "nope") {
            Err(e @ IoError::MissingField { .. }) => {
                let m = e.to_string();
                assert!(m.contains("flag, items, fixed, bounded, ok, tail"), "{m}");
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            get(&s, &d, "items"),
            Err(IoError::NonNumeric { .. })
        ));
        assert!(matches!(
            get(&s, &d, "items[0]"),
            Err(IoError::NonNumeric { .. })
        ));
        assert!(matches!(
            get(&s, &d, "fixed[0].name"),
            Err(IoError::NonNumeric { .. })
        ));
        assert!(matches!(
            get(&s, &d, "tail.x"),
            Err(IoError::MissingField { .. })
        ));
        for n in 0..d.len() {
            assert!(get(&s, &d[..n], "tail").is_err());
        }
    }
}

#[test]
fn stamped_scalar_full_message() {
    let s = Ros2Schema::parse("hbn_msgs/msg/StampedScalar", &stamped_scalar_ros2msg()).unwrap();
    let d = stamped_scalar_cdr(1_700_000_000, 123_456_789, "", -0.75);
    assert_eq!(d.len(), 28);
    assert_eq!(&d[..4], &[0, 1, 0, 0]);
    assert_eq!(&d[12..17], &[1, 0, 0, 0, 0]); // frame_id: length 1, NUL
    assert_eq!(get(&s, &d, "header.stamp.sec").unwrap(), 1_700_000_000.0);
    assert_eq!(get(&s, &d, "header.stamp.nanosec").unwrap(), 123_456_789.0);
    assert_eq!(get(&s, &d, "data").unwrap(), -0.75);
    let d = stamped_scalar_cdr(5, 6, "base_link", 8.25);
    assert_eq!(get(&s, &d, "data").unwrap(), 8.25);
    assert_eq!(get(&s, &d, "header.stamp.nanosec").unwrap(), 6.0);
    // unknown encapsulation
    let mut bad = d.clone();
    bad[1] = 0x02;
    assert!(matches!(
        get(&s, &bad, "data"),
        Err(IoError::BadMessage { .. })
    ));
}

#[test]
fn parse_stamped_scalar_schema() {
    let s = Ros2Schema::parse("hbn_msgs/msg/StampedScalar", &stamped_scalar_ros2msg()).unwrap();
    let root = s.root_type().unwrap();
    assert_eq!(root.name, "hbn_msgs/StampedScalar");
    assert_eq!(root.fields.len(), 2);
    assert_eq!(root.fields[0].name, "header");
    assert_eq!(root.fields[1].ty, FieldType::Prim(Prim::F64));
    let FieldType::Msg(h) = root.fields[0].ty else {
        panic!()
    };
    let header = &s.types[h];
    assert_eq!(header.name, "std_msgs/Header");
    assert_eq!(header.fields[1].ty, FieldType::Prim(Prim::String));
    let FieldType::Msg(t) = header.fields[0].ty else {
        panic!()
    };
    assert_eq!(s.types[t].name, "builtin_interfaces/Time");
    assert_eq!(s.types[t].fields[0].ty, FieldType::Prim(Prim::I32));
    assert_eq!(s.types[t].fields[1].ty, FieldType::Prim(Prim::U32));
}

#[test]
fn parse_joint_state_like_schema_with_builtins() {
    // No Header / Time sections: resolved as built-ins.
    let text = "Header header\nstring[] name\nfloat64[] position\nfloat64[6] velocity\n\
                float64[<=10] effort\nstring<=5[<=2] tags\n\
                int32 FOO=1\nstring BAR = \"x#y\"\nfloat64 gain 0.5 # default\n# comment\n\n\
                builtin_interfaces/Duration d\n";
    let s = Ros2Schema::parse("sensor_msgs/msg/JointState", text).unwrap();
    let r = s.root_type().unwrap();
    let names: Vec<&str> = r.fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "header", "name", "position", "velocity", "effort", "tags", "gain", "d"
        ]
    );
    assert_eq!(r.fields[1].array, ArrayKind::Unbounded);
    assert_eq!(r.fields[3].array, ArrayKind::Fixed(6));
    assert_eq!(r.fields[4].array, ArrayKind::Bounded(10));
    assert_eq!(r.fields[5].ty, FieldType::Prim(Prim::String));
    assert_eq!(r.fields[5].array, ArrayKind::Bounded(2));
    let FieldType::Msg(h) = r.fields[0].ty else {
        panic!()
    };
    assert_eq!(s.types[h].name, "std_msgs/Header");

    // Decode: header, names, positions, velocity (fixed), effort (empty bounded) ...
    let mut w = W::new(true);
    w.i32(10);
    w.u32(20);
    w.string("frame");
    w.u32(2);
    w.string("a");
    w.string("bc");
    w.u32(0); // empty position: no alignment padding after the length
    for k in 0..6 {
        w.f64(k as f64);
    }
    w.u32(1);
    w.f64(7.5);
    w.u32(0);
    w.f64(0.125);
    w.i32(3);
    w.u32(4);
    assert_eq!(get(&s, &w.b, "header.stamp.nanosec").unwrap(), 20.0);
    assert_eq!(get(&s, &w.b, "velocity[5]").unwrap(), 5.0);
    assert_eq!(get(&s, &w.b, "effort[0]").unwrap(), 7.5);
    assert_eq!(get(&s, &w.b, "gain").unwrap(), 0.125);
    assert_eq!(get(&s, &w.b, "d.nanosec").unwrap(), 4.0);
    assert!(matches!(
        get(&s, &w.b, "position[0]"),
        Err(IoError::MissingField { .. })
    ));
}

#[test]
fn bad_schemas() {
    for (text, needle) in [
        ("Foo x\n", "Foo"),
        ("float64\n", "no field name"),
        ("float64[abc] x\n", "array size"),
        ("A a\n===\nMSG: pkg/A\nA inner\n", "contains itself"),
        ("float64 x\n=====\nnot a msg line\n", "MSG:"),
    ] {
        match Ros2Schema::parse("pkg/msg/T", text) {
            Err(e @ IoError::BadSchema { .. }) => {
                let m = e.to_string();
                assert!(m.contains(needle), "{m}");
                assert!(m.contains("pkg/msg/T"), "{m}");
            }
            other => panic!("{text:?}: {other:?}"),
        }
    }
}

#[test]
fn wstring_is_rejected_clearly() {
    let s = Ros2Schema::parse("pkg/msg/W", "wstring w\nfloat64 x\n").unwrap();
    let mut w = W::new(true);
    w.u32(0);
    w.f64(1.0);
    match get(&s, &w.b, "x") {
        Err(e) => assert!(e.to_string().contains("wstring"), "{e}"),
        Ok(v) => panic!("{v}"),
    }
}

#[test]
fn random_bytes_never_panic() {
    let s = Ros2Schema::parse("pkg/msg/Outer", OUTER).unwrap();
    let mut x: u64 = 0x9E3779B97F4A7C15;
    for len in 0..400 {
        let mut d = vec![0u8, 1, 0, 0];
        for _ in 0..len {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            d.push((x >> 24) as u8);
        }
        for path in ["tail", "items[-1].xs[-1]", "bounded[1]", "fixed[1].v"] {
            let _ = get(&s, &d, path);
        }
    }
}
