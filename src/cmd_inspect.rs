//! `vbim inspect FILE [--json]`

use crate::cli::InspectArgs;

pub fn run(_a: InspectArgs) -> Result<(), String> {
    Err("inspect: not yet".into())
}
