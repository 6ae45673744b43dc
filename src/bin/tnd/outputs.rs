//! A command's output claimed from its flags ([`tactile_derender::io::output`]): locked, never one of its inputs,
//! never a folder or file of someone else's without `--force`.

use std::path::Path;

use anyhow::Result;
use tactile_derender::io::output::{claim, Claim, Claimed};

/// Claim the output folder `path`, named by `flag`.
pub fn folder(flag: &str, path: &Path, force: bool, inputs: &[&Path]) -> Result<Claimed> {
    with(Claim::folder(flag, path), force, inputs, &|_| false)
}

/// Claim the output file `path`, named by `flag`; an existing file is replaced when `ours` recognises it as this
/// command's output, or with `force`.
pub fn file(
    flag: &str,
    path: &Path,
    force: bool,
    inputs: &[&Path],
    ours: &dyn Fn(&Path) -> bool,
) -> Result<Claimed> {
    with(Claim::file(flag, path), force, inputs, ours)
}

fn with(
    claim_of: Claim<'_>,
    force: bool,
    inputs: &[&Path],
    ours: &dyn Fn(&Path) -> bool,
) -> Result<Claimed> {
    Ok(claim(
        claim_of
            .force(force)
            .inputs(inputs.iter().copied())
            .ours(ours),
    )?)
}
