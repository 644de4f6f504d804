//! Where a report or a model file came from: the commit the binary was built from (recorded by `build.rs`).

/// The commit this binary was built from: a 12-digit short hash, `+dirty` when tracked files differed from it at
/// build time, or "unknown" when built outside a git checkout.
pub fn commit() -> &'static str {
    env!("SUPINE_BUILD_COMMIT")
}

#[cfg(test)]
mod tests {
    use super::commit;

    #[test]
    fn the_build_commit_is_a_short_hash_or_unknown() {
        let c = commit();
        let hash = c.strip_suffix("+dirty").unwrap_or(c);
        assert!(
            c == "unknown"
                || ((12..=40).contains(&hash.len()) && hash.bytes().all(|b| b.is_ascii_hexdigit())),
            "unexpected build commit {c:?}"
        );
    }
}
