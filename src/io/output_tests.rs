#![allow(clippy::unwrap_used)]
use super::*;
use crate::io::atomic::replace_dir_atomic;
use crate::io::write_atomic;

fn user_tree(dir: &Path) {
    std::fs::create_dir_all(dir.join("notes")).unwrap();
    std::fs::write(dir.join("README.md"), "mine").unwrap();
    std::fs::write(dir.join("config.json"), "{\"mine\": true}").unwrap();
    std::fs::write(dir.join("notes/a.txt"), "a").unwrap();
}

fn assert_user_tree(dir: &Path) {
    assert_eq!(std::fs::read(dir.join("README.md")).unwrap(), b"mine");
    assert_eq!(
        std::fs::read(dir.join("config.json")).unwrap(),
        b"{\"mine\": true}"
    );
    assert_eq!(std::fs::read(dir.join("notes/a.txt")).unwrap(), b"a");
}

#[test]
fn a_new_folder_is_tnds_and_a_foreign_one_needs_force_and_keeps_its_files() {
    let tmp = tempfile::tempdir().unwrap();
    let new = tmp.path().join("run");
    // A claim that writes nothing leaves no folder.
    drop(claim(Claim::folder("--out", &new)).unwrap());
    assert!(!new.exists());
    let c = claim(Claim::folder("--out", &new)).unwrap();
    assert!(is_tnd_folder(&new));
    write_atomic(&c.path().join("README.md"), b"tnd's").unwrap();
    drop(c);
    // The folder is tnd's from now on: a rerun needs no --force and may replace what tnd wrote.
    let c = claim(Claim::folder("--out", &new)).unwrap();
    write_atomic(&c.path().join("README.md"), b"tnd's again").unwrap();
    drop(c);

    let proj = tmp.path().join("proj");
    user_tree(&proj);
    let e = claim(Claim::folder("--out", &proj))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("README.md") && e.contains("3 entries") && e.contains("--force"),
        "{e}"
    );
    assert!(!is_tnd_folder(&proj), "a refused claim writes nothing");
    let c = claim(Claim::folder("--out", &proj).force(true)).unwrap();
    let e = write_atomic(&c.path().join("README.md"), b"x")
        .unwrap_err()
        .to_string();
    assert!(e.contains("not written by tnd"), "{e}");
    assert!(
        write_atomic(&c.path().join("notes/b.txt"), b"x").is_err(),
        "under a user folder"
    );
    write_atomic(&c.path().join("model.json"), b"ours").unwrap();
    // A folder replaced whole keeps the user's files (the same files: hard links) and may not replace them.
    let ino = |p: &Path| {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(p).unwrap().ino()
    };
    let before = ino(&proj.join("README.md"));
    replace_dir_atomic(c.path(), |t| std::fs::write(t.join("model.json"), "new")).unwrap();
    assert_eq!(ino(&proj.join("README.md")), before);
    let e = replace_dir_atomic(c.path(), |t| std::fs::write(t.join("config.json"), "new"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("config.json") && e.contains("not written by tnd"),
        "{e}"
    );
    drop(c);
    assert_user_tree(&proj);
    // The ledger remembers: the next run, without --force, still may not touch them.
    let c = claim(Claim::folder("--out", &proj)).unwrap();
    assert!(write_atomic(&c.path().join("config.json"), b"x").is_err());
    drop(c);
    assert_user_tree(&proj);
    // Released: this process may write there again outside a claim (the workbench's own files).
    write_atomic(&proj.join("other.txt"), b"x").unwrap();
}

#[test]
fn a_file_output_replaces_only_its_own_or_with_force() {
    let tmp = tempfile::tempdir().unwrap();
    let f = tmp.path().join("victim.mcap");
    std::fs::write(&f, "a real recording").unwrap();
    let e = claim(Claim::file("--out", &f)).unwrap_err().to_string();
    assert!(e.contains("victim.mcap") && e.contains("--force"), "{e}");
    let no = |_: &Path| false;
    assert!(claim(Claim::file("--out", &f).ours(&no)).is_err());
    // Of the command's format, but not as tnd left it (tnd never wrote it): still the user's.
    let yes = |p: &Path| std::fs::read(p).is_ok_and(|b| b.starts_with(b"a real"));
    assert!(claim(Claim::file("--out", &f).ours(&yes)).is_err());
    // Written by tnd under a claim, it is tnd's to replace; edited by the user since, it is theirs again.
    let c = claim(Claim::file("--out", &f).force(true)).unwrap();
    write_atomic(c.path(), b"a real recording, by tnd").unwrap();
    drop(c);
    drop(claim(Claim::file("--out", &f).ours(&yes)).unwrap());
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&f, "a real recording, edited").unwrap();
    assert!(claim(Claim::file("--out", &f).ours(&yes)).is_err());
    std::fs::write(&f, "a real recording").unwrap();
    // An output that is an input is refused even with --force; so is a folder that holds one.
    let e = claim(Claim::file("--out", &f).force(true).inputs([&f]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("also an input"), "{e}");
    let e = claim(Claim::folder("--out", tmp.path()).force(true).inputs([&f]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("holds an input"), "{e}");
    // A file is never turned into a folder, nor a folder into a file.
    let e = claim(Claim::folder("--diffusers", &f).force(true))
        .unwrap_err()
        .to_string();
    assert!(e.contains("is a file, not a folder"), "{e}");
    let e = claim(Claim::file("--out", tmp.path()).force(true))
        .unwrap_err()
        .to_string();
    assert!(e.contains("is a folder"), "{e}");
    assert_eq!(std::fs::read(&f).unwrap(), b"a real recording");
}

#[test]
fn root_home_and_the_current_folder_are_refused_even_with_force() {
    for p in [
        Path::new("/"),
        Path::new("."),
        Path::new(".."),
        Path::new("./no_such_folder/.."),
        Path::new("/no_such_folder/.."),
    ] {
        let e = claim(Claim::folder("--out", p).force(true))
            .unwrap_err()
            .to_string();
        assert!(e.contains("root") || e.contains("current folder"), "{e}");
    }
    if let Some(home) = std::env::var_os("HOME").filter(|h| Path::new(h).is_dir()) {
        let e = claim(Claim::folder("--out", Path::new(&home)).force(true))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("home") || e.contains("current folder") || e.contains("root"),
            "{e}"
        );
    }
}

#[test]
fn a_symbolic_link_is_claimed_as_its_target_and_shares_its_lock() {
    let tmp = tempfile::tempdir().unwrap();
    let real = tmp.path().join("dsC");
    let link = tmp.path().join("lnkC");
    std::fs::create_dir(&real).unwrap();
    std::os::unix::fs::symlink(&real, &link).unwrap();
    let c = claim(Claim::folder("--out", &real)).unwrap();
    let e = claim(Claim::folder("--out", &link))
        .unwrap_err()
        .to_string();
    assert!(e.contains("in use by another tnd run"), "{e}");
    drop(c);
    let c = claim(Claim::folder("--out", &link)).unwrap();
    assert_eq!(c.path(), std::fs::canonicalize(&real).unwrap());
    drop(c);
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    // A link to nowhere names its target.
    let dangling = tmp.path().join("dangling");
    std::os::unix::fs::symlink(tmp.path().join("gone"), &dangling).unwrap();
    let e = claim(Claim::file("--out", &dangling))
        .unwrap_err()
        .to_string();
    assert!(e.contains("symbolic link") && e.contains("gone"), "{e}");
}

#[test]
fn a_fifo_is_refused_and_carried_across_a_replacement_unread() {
    let tmp = tempfile::tempdir().unwrap();
    let fifo = tmp.path().join("pipe");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid NUL-terminated path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let e = claim(Claim::file("--out", &fifo).force(true))
        .unwrap_err()
        .to_string();
    assert!(e.contains("FIFO"), "{e}");
    // Inside a folder replaced whole (an export with --force), the FIFO is linked, never opened (that would hang).
    let claimed = claim(Claim::folder("--out", tmp.path().join("x").as_path())).unwrap();
    drop(claimed);
    let dir = tmp.path().to_path_buf();
    let out = dir.join("export");
    std::fs::create_dir(&out).unwrap();
    std::fs::rename(&fifo, out.join("pipe")).unwrap();
    std::fs::create_dir(out.join("real_dir")).unwrap();
    std::os::unix::fs::symlink(out.join("real_dir"), out.join("linked_dir")).unwrap();
    let c = claim(Claim::folder("--out", &out).force(true)).unwrap();
    replace_dir_atomic(c.path(), |t| std::fs::write(t.join("model.json"), "m")).unwrap();
    let t = |n: &str| std::fs::symlink_metadata(out.join(n)).unwrap().file_type();
    use std::os::unix::fs::FileTypeExt;
    assert!(t("pipe").is_fifo());
    assert!(t("linked_dir").is_symlink(), "a linked folder stays a link");
    assert!(out.join("model.json").is_file());
}

#[test]
fn a_claim_that_writes_nothing_takes_its_ledger_back() {
    // A command refused after its claim (here: nothing written) never leaves a user's folder marked as tnd's, so the
    // next command still refuses to write there without --force.
    let tmp = tempfile::tempdir().unwrap();
    let proj = tmp.path().join("proj");
    user_tree(&proj);
    drop(claim(Claim::folder("--out", &proj).force(true)).unwrap());
    assert!(!is_tnd_folder(&proj));
    assert!(claim(Claim::folder("--out", &proj)).is_err());
    assert_user_tree(&proj);
    // Once something was written, the ledger stays (a resume after a kill finds it).
    let c = claim(Claim::folder("--out", &proj).force(true)).unwrap();
    write_atomic(&c.path().join("out.json"), b"{}").unwrap();
    drop(c);
    assert!(is_tnd_folder(&proj));
    // A hand-edited ledger naming "" or a path protects no more than its entries.
    std::fs::write(
        proj.join(LEDGER_FILE),
        r#"{"written_by": "tnd", "foreign": ["", "../x", "README.md"], "written": ["out.json"]}"#,
    )
    .unwrap();
    let c = claim(Claim::folder("--out", &proj)).unwrap();
    write_atomic(&c.path().join("out.json"), b"{}").unwrap();
    assert!(write_atomic(&c.path().join("README.md"), b"x").is_err());
    drop(c);
    assert_user_tree(&proj);
    // A file the user adds between runs is theirs, kept like the rest; one a killed run wrote is tnd's (each entry
    // is recorded as it is written), and a file the user adds after the kill is theirs again.
    std::fs::write(proj.join("mean.npy"), "mine").unwrap();
    let c = claim(Claim::folder("--out", &proj)).unwrap();
    assert!(write_atomic(&c.path().join("mean.npy"), b"x").is_err());
    write_atomic(&c.path().join("partial.npy"), b"half").unwrap();
    let ledger = proj.join(LEDGER_FILE);
    let during = std::fs::read_to_string(&ledger).unwrap();
    drop(c);
    // As a kill leaves the ledger: the one written during the run (no end recorded).
    std::fs::write(&ledger, &during).unwrap();
    assert!(
        during.contains("partial.npy") && during.contains("\"running\": true"),
        "{during}"
    );
    std::fs::write(proj.join("added.npy"), "mine too").unwrap();
    let c = claim(Claim::folder("--out", &proj)).unwrap();
    write_atomic(&c.path().join("partial.npy"), b"whole").unwrap();
    assert!(write_atomic(&c.path().join("added.npy"), b"x").is_err());
    drop(c);
    assert_eq!(std::fs::read(proj.join("mean.npy")).unwrap(), b"mine");
    assert_eq!(std::fs::read(proj.join("added.npy")).unwrap(), b"mine too");
    // A symbolic link inside the folder to a folder of the user's elsewhere is not a way out of it.
    let elsewhere = tmp.path().join("elsewhere");
    std::fs::create_dir(&elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, proj.join("shards")).unwrap();
    let c = claim(Claim::folder("--out", &proj)).unwrap();
    let e = write_atomic(&c.path().join("shards/a.npz"), b"x")
        .unwrap_err()
        .to_string();
    assert!(e.contains("symbolic link"), "{e}");
    drop(c);
    assert!(!elsewhere.join("a.npz").exists());
}

#[test]
fn a_file_of_an_input_folder_is_part_of_the_input() {
    let tmp = tempfile::tempdir().unwrap();
    let model = tmp.path().join("model");
    std::fs::create_dir(&model).unwrap();
    let weights = model.join("weights.safetensors");
    std::fs::write(&weights, "weights").unwrap();
    let e = claim(Claim::file("--out", &weights).force(true).inputs([&model]))
        .unwrap_err()
        .to_string();
    assert!(e.contains("part of an input"), "{e}");
    // A new file beside the input's files is no part of it.
    drop(claim(Claim::file("--out", &model.join("notes.json")).inputs([&model])).unwrap());
    assert_eq!(std::fs::read(&weights).unwrap(), b"weights");
}
