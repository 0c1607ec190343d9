//! Tests' side of the tables the crate measures once and stores as source
//! (`measured.rs` files): a fresh measurement against the stored values, and
//! `UPDATE_TABLES=1` to rewrite the file from it.
//!
//! Why stored: each table is a Monte-Carlo measurement on a white-noise field
//! (hundreds of thousands of samples). Measured on first use, they cost every
//! fresh process — one `blind-augment fit`, one worker start — tens of
//! milliseconds before its first fit.

/// One stored table: its Rust name and type, the values the source holds and a
/// fresh measurement (both flattened), and the fresh value as a Rust literal.
pub(crate) struct Table {
    pub name: &'static str,
    pub ty: &'static str,
    pub doc: &'static str,
    pub stored: Vec<f64>,
    pub fresh: Vec<f64>,
    pub literal: String,
}

/// Compares each table's stored values with the fresh ones; with `UPDATE_TABLES=1`
/// writes `rel_path` (relative to the crate root) from the fresh ones instead.
///
/// Tolerance: |stored − fresh| ≤ 1e-5·|fresh| + 1e-7·max|fresh|. The tables'
/// own sampling error is ≥ 1e-3 relative, so no change to the code that measures
/// them that matters to a fit stays inside it; what does stay inside is the last-ulp
/// difference of `ln`/`cos` between C libraries (the field's Box–Muller) and the
/// f32 → decimal → f32 round trip of the source (exact).
pub(crate) fn check(rel_path: &str, file_doc: &str, tables: &[Table]) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel_path);
    if std::env::var_os("UPDATE_TABLES").is_some_and(|v| v == "1") {
        let mut src = format!(
            "//! {file_doc}\n//!\n//! Generated: `UPDATE_TABLES=1 cargo test --lib measured_tables`. Do not edit.\n"
        );
        for t in tables {
            src += &format!("\n{}\n#[rustfmt::skip]\npub(crate) static {}: {} = {};\n", t.doc, t.name, t.ty, t.literal);
        }
        std::fs::write(&path, src).unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        return;
    }
    for t in tables {
        assert_eq!(t.stored.len(), t.fresh.len(), "{}: stored and fresh sizes differ", t.name);
        let scale = t.fresh.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (i, (s, f)) in t.stored.iter().zip(&t.fresh).enumerate() {
            assert!(
                (s - f).abs() <= 1e-5 * f.abs() + 1e-7 * scale,
                "{} in {}: element {i} is stored as {s}, measured {f}; rerun with UPDATE_TABLES=1",
                t.name,
                path.display()
            );
        }
    }
}
