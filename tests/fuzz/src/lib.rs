//! The body of every fuzz target: write the input as the reader's file in a scratch copy of the
//! seed files (`tests::readers`), read it, and fail (abort, so libFuzzer keeps the input) when
//! the reader panics or returns an error that does not name the file. libFuzzer's own
//! `-rss_limit_mb` and `-timeout` bound memory and time.

use tests::readers::Fixture;

thread_local! {
    static FIXTURE: Fixture = Fixture::new();
}

/// Runs reader `name` on `data`.
pub fn check(name: &str, data: &[u8]) {
    FIXTURE.with(|f| {
        let reader = f
            .reader(name)
            .unwrap_or_else(|| panic!("no reader {name:?}"));
        let file = reader
            .file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Err(e) = f.run(reader, data) {
            assert!(e.contains(&file), "error does not name {file}: {e}");
        }
    });
}
