//! Replays the files the `player_decoder` fuzz target starts from and every input kept in
//! `fuzz/regressions/` through the player's decoder (what a game's player does with a file
//! before the GPU): each must return, whatever the bytes.

use std::path::Path;

#[test]
fn every_kept_input_is_handled_by_the_players_decoder() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fuzz");
    let mut n = 0;
    for dir in [
        "seeds/decode",
        "regressions/decode",
        "regressions/player_decoder",
    ] {
        let Ok(files) = std::fs::read_dir(root.join(dir)) else {
            continue;
        };
        for f in files {
            let path = f.unwrap().path();
            eprintln!("{}", path.display());
            vbim_player::bench::fuzz_decoder(&std::fs::read(&path).unwrap());
            n += 1;
        }
    }
    assert!(n > 0);
}
