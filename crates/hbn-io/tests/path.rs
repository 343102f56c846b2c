use hbn_io::{IoError, PathElem, SignalPath};

fn f(s: &str) -> PathElem {
    PathElem::Field(s.into())
}

fn parse(s: &str) -> SignalPath {
    match s.parse::<SignalPath>() {
        Ok(p) => p,
        Err(e) => panic!("`{s}` should parse: {e}"),
    }
}

#[test]
fn plain_and_nested() {
    let p = parse("/input.data");
    assert_eq!(p.topic, "/input");
    assert_eq!(p.fields, vec![f("data")]);
    let p = parse("/imu.linear_acceleration.x");
    assert_eq!(p.topic, "/imu");
    assert_eq!(p.fields, vec![f("linear_acceleration"), f("x")]);
    let p = parse("/bare");
    assert_eq!(p.fields, vec![]);
    assert_eq!(p.topic, "/bare");
    let p = parse("imu_no_slash.a");
    assert_eq!(p.topic, "imu_no_slash");
}

#[test]
fn indices() {
    let p = parse("/joint_states.position[1]");
    assert_eq!(p.fields, vec![f("position"), PathElem::Index(1)]);
    let p = parse("/topic.field.sub[2].x");
    assert_eq!(
        p.fields,
        vec![f("field"), f("sub"), PathElem::Index(2), f("x")]
    );
    let p = parse("/a.b[-1]");
    assert_eq!(p.fields, vec![f("b"), PathElem::Index(-1)]);
    let p = parse("/a.m[0][3]");
    assert_eq!(
        p.fields,
        vec![f("m"), PathElem::Index(0), PathElem::Index(3)]
    );
}

#[test]
fn quoted_topic_and_field() {
    let p = parse("\"/a.b\".field");
    assert_eq!(p.topic, "/a.b");
    assert_eq!(p.fields, vec![f("field")]);
    let p = parse("\"/we\\\"ird[x]\".\"f.g\"[0]");
    assert_eq!(p.topic, "/we\"ird[x]");
    assert_eq!(p.fields, vec![f("f.g"), PathElem::Index(0)]);
}

#[test]
fn display_round_trips() {
    for s in [
        "/input.data",
        "/joint_states.position[1]",
        "/topic.field.sub[2].x",
        "/a.b[-3]",
        "\"/a.b\".field",
        "\"/we\\\"ird[x]\".\"f.g\"[0]",
        "/bare",
    ] {
        let p = parse(s);
        let shown = p.to_string();
        assert_eq!(parse(&shown), p, "{s} -> {shown}");
    }
    assert_eq!(parse("\"/a.b\".field").to_string(), "\"/a.b\".field");
    assert_eq!(parse("/x.y[2].z").to_string(), "/x.y[2].z");
    let p = SignalPath {
        topic: "/t with space".into(),
        fields: vec![f("a\\b"), PathElem::Index(-7), f("")],
    };
    assert_eq!(parse(&p.to_string()), p);
}

#[test]
fn malformed_paths_are_errors() {
    for s in [
        "",
        "   ",
        ".data",
        "/a.",
        "/a..b",
        "/a[",
        "/a[x]",
        "/a[1:3]",
        "/a.b]",
        "\"/a.b",
        "/a.b{c==1}",
        "/a.b c",
        "/a[1]x",
        "/a.\"b",
        "[0]",
    ] {
        match s.parse::<SignalPath>() {
            Err(IoError::BadPath { path, reason }) => {
                assert_eq!(path, s);
                assert!(!reason.is_empty());
                let msg = IoError::BadPath { path, reason }.to_string();
                assert!(msg.contains("expected `/topic.field"), "{msg}");
            }
            other => panic!("`{s}` should be BadPath, got {other:?}"),
        }
    }
}

#[test]
fn serde_round_trip() {
    let p = parse("/a.b[2]");
    let j = serde_json::to_string(&p).unwrap();
    let q: SignalPath = serde_json::from_str(&j).unwrap();
    assert_eq!(p, q);
}
