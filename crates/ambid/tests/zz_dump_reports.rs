mod common;
use ambid::workflow::{self, Progress, Verbosity, WorkflowConfig};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

#[test]
fn dump() {
    let dir = PathBuf::from(std::env::var("DUMP_DIR").unwrap());
    std::fs::create_dir_all(&dir).unwrap();
    let mut cases: Vec<(String, WorkflowConfig, PathBuf)> =
        vec![("twin".into(), WorkflowConfig::default(), PathBuf::from("."))];
    for n in ["robot-arm.toml", "maglev.toml"] {
        let p = root().join("examples/workflows").join(n);
        let cfg = WorkflowConfig::from_path(&p).unwrap();
        cases.push((n.into(), cfg, p.parent().unwrap().to_path_buf()));
    }
    let mut extra = Vec::new();
    for (name, cfg, base) in &cases {
        let mut c = cfg.clone();
        c.steps = Some(vec![workflow::Step::Frf, workflow::Step::Order]);
        c.order.na_max = 3;
        c.order.nb_max = 3;
        extra.push((format!("{name}_fo"), c, base.clone()));
    }
    cases.extend(extra);
    for (name, cfg, base) in cases {
        let out = workflow::run(&cfg, &base, &mut Progress::new(Verbosity::Quiet)).unwrap();
        let html = out.report.to_html();
        std::fs::write(dir.join(format!("{name}.html")), html).unwrap();
    }
}
