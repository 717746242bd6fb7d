//! One section of the performance page run again on its own and written
//! into the page in place (`--perf --section NAME`): the character scene's
//! table takes minutes, where the whole page takes a quarter of an hour,
//! and a change to the character solver wants its rows before and after,
//! the same day, on the same machine.

use std::fmt::Write as _;

use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};

use super::page::{character_section, self_collision_section, two_sheets_section};
use super::{PerfConfig, cape_rows, self_collision_rows, two_sheets_rows};

/// The sections `--section` reruns: the name on the command line and the
/// heading it replaces on the page (up to the next `## ` heading; the
/// self-collision section holds its cloth-against-cloth table).
pub const SECTIONS: [(&str, &str); 2] = [
    ("character", "## Character cloth"),
    ("self-collision", "## Self-collision"),
];

/// Runs the section named `name` (one of [`SECTIONS`]) again and writes it
/// into `config.out_dir`'s `perf.md` in place of the old one, followed by a
/// line saying it was rerun on its own (so its rows are compared with each
/// other, not with the rest of the page, which another run wrote). Returns
/// the new page. A name that is not a section, or a page without the
/// section's heading, is an error and leaves the page as it was.
pub fn rerun_section(config: &PerfConfig, name: &str) -> std::io::Result<String> {
    let Some(&(_, heading)) = SECTIONS.iter().find(|(n, _)| *n == name) else {
        let names: Vec<_> = SECTIONS.iter().map(|(n, _)| *n).collect();
        return Err(std::io::Error::other(format!(
            "--section {name}: the sections are {}",
            names.join(", ")
        )));
    };
    let path = config.out_dir.join("perf.md");
    let page = std::fs::read_to_string(&path)?;
    let start = page
        .find(&format!("{heading}\n"))
        .ok_or_else(|| std::io::Error::other(format!("{} has no {heading}", path.display())))?;
    let after = start + heading.len();
    let end = page[after..]
        .find("\n## ")
        .map_or(page.len(), |k| after + k + 1);
    // The page's pool, as `run` makes it (the two sheets' app uses it).
    ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    let mut section = String::new();
    match name {
        "character" => character_section(&mut section, &cape_rows(config), config.cape_steps),
        _ => {
            self_collision_section(&mut section, &self_collision_rows(config));
            two_sheets_section(&mut section, &two_sheets_rows(config));
        }
    }
    writeln!(
        section,
        "This section was rerun on its own (`--perf --section {name}`) on {}; the rest of \
         the page is from another run, so compare this section's rows with each other.",
        crate::chart::machine()
    )
    .ok();
    writeln!(section).ok();
    let page = format!("{}{section}{}", &page[..start], &page[end..]);
    std::fs::write(&path, &page)?;
    Ok(page)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_section_is_rerun_in_place_and_the_rest_of_the_page_kept() {
        let dir = std::env::temp_dir().join(format!("bevy_cloth_section_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let old = "# Performance\n\nbefore\n\n## Character cloth\n\nold rows\n\n\
                   ## Self-collision\n\nkept rows\n";
        let path = dir.join("perf.md");
        std::fs::write(&path, old).unwrap();
        let config = PerfConfig::tiny(&dir);
        let page = rerun_section(&config, "character").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), page);
        assert!(page.starts_with("# Performance\n\nbefore\n\n## Character cloth\n"));
        assert!(!page.contains("old rows"), "{page}");
        assert!(page.contains("| cape vertices | method |"), "{page}");
        assert!(page.contains("rerun on its own (`--perf --section character`)"));
        assert!(
            page.ends_with("\n\n## Self-collision\n\nkept rows\n"),
            "{page}"
        );
        // An unknown section, and a page without the heading: errors, the
        // page unchanged.
        let err = rerun_section(&config, "capes").unwrap_err();
        assert!(
            err.to_string().contains("character, self-collision"),
            "{err}"
        );
        std::fs::write(&path, "# Performance\n").unwrap();
        assert!(rerun_section(&config, "self-collision").is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "# Performance\n");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
