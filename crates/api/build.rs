//! Records the commit being built. The gRPC code is generated ahead, not here
//! (`src/generated/`, `scripts/protogen.sh`): compiling protox and its regex in every build
//! cost about 50 CPU-seconds of a cold one.

/// The commit being built, for `segsplat_build_info`: `SEGSPLAT_GIT_COMMIT` when the build sets
/// it (an image built without `.git`), else `git rev-parse`, else `unknown`. Reruns when HEAD
/// moves (only paths that exist are watched: a missing one would rerun every build).
fn git_commit() -> String {
    println!("cargo:rerun-if-env-changed=SEGSPLAT_GIT_COMMIT");
    if let Ok(commit) = std::env::var("SEGSPLAT_GIT_COMMIT") {
        return commit;
    }
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|output| output.status.success())
            .map(|output| String::from_utf8_lossy(&output.stdout).trim().to_string())
    };
    for path in [
        git(&["rev-parse", "--git-path", "HEAD"]),
        git(&["rev-parse", "--symbolic-full-name", "HEAD"])
            .and_then(|name| git(&["rev-parse", "--git-path", &name])),
    ]
    .into_iter()
    .flatten()
    {
        if std::path::Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
    git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".to_string())
}

fn main() {
    println!("cargo:rustc-env=SEGSPLAT_GIT_COMMIT={}", git_commit());
}
