//! Replays the fuzz targets' seeds and every input kept in `fuzz/regressions/` (crashes the
//! fuzzer found, and the hostile files of the project's history) through the same entry
//! points the targets call: each must return, whatever the bytes.

use std::path::Path;

fn replay(target: &str, run: fn(&[u8])) -> usize {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz");
    let mut n = 0;
    for dir in ["seeds", "regressions"] {
        let Ok(files) = std::fs::read_dir(root.join(dir).join(target)) else {
            continue;
        };
        for f in files {
            let path = f.unwrap().path();
            let data = std::fs::read(&path).unwrap();
            eprintln!("{target}: {}", path.display());
            run(&data);
            n += 1;
        }
    }
    n
}

#[test]
fn every_kept_input_is_handled() {
    assert!(replay("container", vbim_format::fuzz::container) > 0);
    assert!(replay("decode", vbim_format::fuzz::decode) > 0);
    assert!(replay("chunks", vbim_format::fuzz::chunks) > 0);
    assert!(replay("plane2", vbim_format::fuzz::plane2) > 0);
    assert!(replay("package", vbim_format::fuzz::package) > 0);
}
