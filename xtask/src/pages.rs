//! The figures a command measured, written between `<!-- NAME:start -->` and
//! `<!-- NAME:end -->` markers on the pages that show them, and the files a command writes.
//!
//! Every page is read and every region found before any page is written (a page without its
//! markers leaves every page as it was), and each page is written whole to a temporary file
//! beside it and renamed over it, as psmpa-sim writes its outputs
//! ([`psmpa_sim::cli::files::Output`]): a write that fails midway (a full disk, a file-size
//! limit) leaves the page as it was.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use psmpa_sim::cli::files::Output;

/// Puts `text` between `<!-- NAME:start -->` and `<!-- NAME:end -->` in `path`: the figures a
/// command measured, on the page that shows them.
pub fn write_between(path: &Path, name: &str, text: &str) -> Result<(), String> {
    write_pages(&[(path.to_path_buf(), name, text.to_owned())])
}

/// Writes each `(page, NAME, text)` region, after checking every page's markers.
pub fn write_pages(regions: &[(PathBuf, &str, String)]) -> Result<(), String> {
    let mut pages: Vec<(PathBuf, String, String)> = Vec::new();
    for (path, name, text) in regions {
        let at = match pages.iter().position(|(p, _, _)| p == path) {
            Some(i) => i,
            None => {
                let page = read_page(path)?;
                pages.push((path.clone(), page.clone(), page));
                pages.len() - 1
            }
        };
        let updated = &mut pages[at].2;
        let (from, to) = region(updated, path, name)?;
        *updated = format!("{}{text}{}", &updated[..from], &updated[to..]);
    }
    for (path, old, new) in &pages {
        if old != new {
            write_file(path, new.as_bytes())?;
        }
    }
    Ok(())
}

/// Checks that each `(page, NAME)` has one pair of markers, in order: before a long run whose
/// figures go there.
pub fn check_pages(regions: &[(PathBuf, &str)]) -> Result<(), String> {
    for (path, name) in regions {
        region(&read_page(path)?, path, name)?;
    }
    Ok(())
}

/// Writes `bytes` to `path` whole: a temporary file beside it, renamed over it.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let mut out = Output::create(path)?;
    out.write_all(bytes)
        .map_err(|e| format!("{}: cannot write: {e}", path.display()))?;
    out.commit()
}

/// A page: a regular file (a FIFO would wait for ever), read as UTF-8.
fn read_page(path: &Path) -> Result<String, String> {
    let meta = std::fs::metadata(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if !meta.is_file() {
        return Err(format!(
            "{}: not a regular file: a page the figures are written into must be one",
            path.display()
        ));
    }
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

/// The byte range between the one pair of `name`'s markers in `page`.
fn region(page: &str, path: &Path, name: &str) -> Result<(usize, usize), String> {
    let (start, end) = (
        format!("<!-- {name}:start -->"),
        format!("<!-- {name}:end -->"),
    );
    let starts: Vec<usize> = page.match_indices(&start).map(|(i, _)| i).collect();
    let ends: Vec<usize> = page.match_indices(&end).map(|(i, _)| i).collect();
    match (starts.as_slice(), ends.as_slice()) {
        ([a], [b]) => {
            let from = a + start.len();
            if *b < from {
                Err(format!(
                    "{}: its {name}:end marker comes before its {name}:start marker",
                    path.display()
                ))
            } else {
                Ok((from, *b))
            }
        }
        ([], _) | (_, []) => Err(format!(
            "{}: no {name}:start and {name}:end markers",
            path.display()
        )),
        (s, e) => Err(format!(
            "{}: {} {name}:start and {} {name}:end markers: one pair expected",
            path.display(),
            s.len(),
            e.len()
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir() -> tempfile_dir::Dir {
        tempfile_dir::Dir::new()
    }

    /// A folder of its own under the target directory, removed after the test.
    mod tempfile_dir {
        pub struct Dir(pub std::path::PathBuf);
        impl Dir {
            pub fn new() -> Self {
                use std::sync::atomic::{AtomicUsize, Ordering};
                static N: AtomicUsize = AtomicUsize::new(0);
                let p = std::env::temp_dir().join(format!(
                    "xtask-pages-{}-{}",
                    std::process::id(),
                    N.fetch_add(1, Ordering::Relaxed)
                ));
                let _ = std::fs::remove_dir_all(&p);
                std::fs::create_dir_all(&p).unwrap();
                Self(p)
            }
        }
        impl Drop for Dir {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.0);
            }
        }
    }

    const PAGE: &str = "a\n<!-- x:start -->old<!-- x:end -->\nb\n";

    #[test]
    fn a_page_without_markers_leaves_every_page_as_it_was() {
        let d = dir();
        let (good, bad) = (d.0.join("good.md"), d.0.join("bad.md"));
        std::fs::write(&good, PAGE).unwrap();
        std::fs::write(&bad, "no markers\n").unwrap();
        let e = write_pages(&[
            (good.clone(), "x", "new".to_owned()),
            (bad.clone(), "x", "new".to_owned()),
        ])
        .unwrap_err();
        assert!(e.contains("bad.md: no x:start"), "{e}");
        assert_eq!(std::fs::read_to_string(&good).unwrap(), PAGE);
    }

    #[test]
    fn regions_of_one_page_are_written_together() {
        let d = dir();
        let p = d.0.join("p.md");
        std::fs::write(&p, format!("{PAGE}<!-- y:start --><!-- y:end -->\n")).unwrap();
        write_pages(&[
            (p.clone(), "x", "1".to_owned()),
            (p.clone(), "y", "2".to_owned()),
        ])
        .unwrap();
        assert_eq!(
            std::fs::read_to_string(&p).unwrap(),
            "a\n<!-- x:start -->1<!-- x:end -->\nb\n<!-- y:start -->2<!-- y:end -->\n"
        );
        // No temporary file left beside it.
        assert_eq!(std::fs::read_dir(&d.0).unwrap().count(), 1);
    }

    #[test]
    fn an_early_end_marker_and_a_second_pair_are_named() {
        let d = dir();
        let p = d.0.join("p.md");
        std::fs::write(&p, format!("<!-- x:end -->{PAGE}")).unwrap();
        let e = write_between(&p, "x", "new").unwrap_err();
        assert!(e.contains("1 x:start and 2 x:end markers"), "{e}");
        std::fs::write(&p, format!("{PAGE}{PAGE}")).unwrap();
        let e = write_between(&p, "x", "new").unwrap_err();
        assert!(e.contains("2 x:start and 2 x:end markers"), "{e}");
        std::fs::write(&p, "<!-- x:end --><!-- x:start -->").unwrap();
        let e = write_between(&p, "x", "new").unwrap_err();
        assert!(e.contains("x:end marker comes before its x:start"), "{e}");
    }

    #[test]
    fn a_fifo_page_is_refused_at_once() {
        let d = dir();
        let p = d.0.join("fifo.md");
        let made = std::process::Command::new("mkfifo").arg(&p).status();
        if !made.is_ok_and(|s| s.success()) {
            return;
        }
        let e = write_between(&p, "x", "new").unwrap_err();
        assert!(e.contains("not a regular file"), "{e}");
    }

    #[test]
    fn a_page_is_replaced_whole_not_written_in_place() {
        let d = dir();
        let p = d.0.join("p.md");
        std::fs::write(&p, PAGE).unwrap();
        // A hard link to the old page keeps the old text: the page was renamed over, not
        // truncated and written.
        let link = d.0.join("link.md");
        std::fs::hard_link(&p, &link).unwrap();
        write_between(&p, "x", "new").unwrap();
        assert_eq!(std::fs::read_to_string(&link).unwrap(), PAGE);
        assert!(std::fs::read_to_string(&p).unwrap().contains("new"));
    }
}
