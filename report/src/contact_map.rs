//! The stability map's contact section ([`crate::stability`]): every
//! method on the contact cases ([`crate::contact`], and the two sheets
//! through the plugin, [`crate::two_sheets`]), judged without a reference;
//! written with the whole map, or alone over the section of a written map
//! (`--contact`, [`rerun_contact`]), all rows or some.

use std::fmt::Write as _;

use indicatif::ProgressBar;
use rayon::prelude::*;

use crate::contact::{self, ContactSizes};
use crate::scenarios::contact_methods;
use crate::stability::StabilityConfig;

/// The heading of the map's contact section.
pub(crate) const CONTACT_HEADING: &str = "\n## Contact extreme cases (every method)\n";

/// The heading of the section after it.
const LIMIT_HEADING: &str = "\n## Symplectic Euler's step limit";

/// Runs the contact cases of `config` alone and writes them over the
/// contact section of the `stability.md` already in its folder (from the
/// section's heading to the next one; before the explicit limit's section
/// on a page written without one). Returns the new page.
///
/// With `only`, just the rows whose case name contains it are run again;
/// the others are kept as the page has them (a row the page lacks is run).
pub fn rerun_contact(config: &StabilityConfig, only: Option<&str>) -> std::io::Result<String> {
    let path = config.out_dir.join("stability.md");
    let page = std::fs::read_to_string(&path)?;
    let missing = || std::io::Error::other(format!("{} has no contact section", path.display()));
    let sizes = config.contact.ok_or_else(missing)?;
    // The section, or where it goes on a page written before it existed:
    // before the explicit limit's.
    let (start, end) = match page.find(CONTACT_HEADING) {
        Some(start) => {
            let after = start + CONTACT_HEADING.len();
            let end = page[after..]
                .find("\n## ")
                .map_or(page.len(), |k| after + k);
            (start, end)
        }
        None => {
            let at = page.find(LIMIT_HEADING).ok_or_else(missing)?;
            (at, at)
        }
    };
    // The rows kept: each line of the old table whose case `only` leaves.
    let old = &page[start..end];
    let kept = |name: &str| -> Option<String> {
        let only = only?;
        if name.contains(only) {
            return None;
        }
        let head = format!("| {name} |");
        old.lines()
            .find(|l| l.starts_with(&head))
            .map(str::to_owned)
    };
    let mut section = String::new();
    let bar = if config.progress {
        ProgressBar::new(sizes.cases().len() as u64 + 1)
    } else {
        ProgressBar::hidden()
    };
    contact_section(&mut section, sizes, &bar, kept);
    bar.finish_and_clear();
    let page = format!("{}{}\n{}", &page[..start], section.trim_end(), &page[end..]);
    std::fs::write(&path, &page)?;
    Ok(page)
}

/// The contact cases' table: every method of [`contact_methods`] on every
/// case (in parallel), but the rows `kept` gives (a case's name to its row,
/// run again if `None`).
pub(crate) fn contact_section(
    md: &mut String,
    sizes: ContactSizes,
    bar: &ProgressBar,
    kept: impl Fn(&str) -> Option<String>,
) {
    let methods = contact_methods();
    let labels: Vec<String> = methods.iter().map(crate::variant).collect();
    md.push_str(CONTACT_HEADING);
    md.push('\n');
    writeln!(
        md,
        "Cotton at 60 Hz, stepped as the plugin steps it: self-collision (thickness 0.9 of \
         the shortest edge, friction 0.3) in `stiff`'s substeps, after each of PBD's \
         iterations, as penalty terms of the objective of `pd`, `pd-anderson`, `newton` and \
         `exact` (and after their step), and after the other methods' steps; the colliders \
         swept after every step, and moved through `stiff`'s substeps. The exact method's \
         contacts and pairs are penalties, not the position-based ones, so there is no reference: \
         a cell is judged by what a player would see. **Folded**: a {0}² sheet of 1 m folded \
         in four (layers 1.3 thicknesses apart) dropped 5 cm onto the ground, {1} s: the exact \
         check's count of mesh edges through one of the sheet's own triangles, the most after \
         any step; the **thin** fold is the same at 0.3 of the edges thick (layers as far \
         apart as the default's), where vertex pairs alone let layers through and \
         vertex–triangle and edge–edge pairs keep them apart, the first also in the objective \
         of `pd`, `pd-anderson`, `newton` and `exact`, the second also in `newton`'s and \
         `exact`'s; the **long** fold is the same at {4}² for {5} s (issue N's \
         target). **Two sheets**: two {6}² sheets of 1 m dropped from 0.65 and 0.9 m (the \
         upper turned by 20°) onto a 30 cm ball on the ground, {7} s, stepped through the \
         plugin (an `App`: each sheet's step sees the other's vertices, and the pass between \
         cloths runs after the steps): the most edges of either sheet through the other's \
         triangles or its own after any step. In every row a cell's ⚑ is the share of steps \
         flagged not converged by the plugin's rule (the method's own relative error over the \
         default tolerance, measured again without what the projection undid; for the two \
         sheets the plugin's own count, the most of either sheet), and a cell with more than \
         {8:.0} % of them is not `✓`: such a sheet moves, but not as implicit Euler would (a \
         stiff sheet locks, and can hang in the air apart and unstretched). \
         **Ball**: a free, level {2}² sheet of 2 m, a ball thrown up through it at \
         30 m/s (half a metre a step) from 0.4 m below it for eight steps: `held` if a ray from the ball's centre \
         along its motion met the sheet after every step and no vertex was left inside the \
         ball. The ball is kinematic (it cannot be slowed), so the sheet must be carried at \
         30 m/s: what strains it is how fast a method's springs pass the pull on (an edge per \
         sweep for the position-based ones). `str` is the largest stretch at any step; `✓` \
         marks 0 through or held with at most {3:.0} % stretch (cotton stretched further has \
         torn); `caught` is the guard's stop. The last column, `stiff chains`, is `stiff` \
         with its chains of stretch springs (rows, columns, diagonals) solved whole in each \
         substep, off in the preset.\n",
        sizes.folded,
        sizes.seconds,
        sizes.ball,
        100.0 * contact::TORN,
        sizes.long.0,
        sizes.long.1,
        sizes.two.cols,
        sizes.two.seconds,
        100.0 * contact::FLAGGED,
    )
    .ok();
    write!(md, "| case |").ok();
    for l in &labels {
        write!(md, " {l} |").ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(labels.len())).ok();
    let mut row = |name: String, cells: &dyn Fn() -> Vec<String>| {
        bar.set_message(name.clone());
        match kept(&name) {
            Some(line) => writeln!(md, "{line}").ok(),
            None => writeln!(md, "| {name} | {} |", cells().join(" | ")).ok(),
        };
        bar.inc(1);
    };
    for case in sizes.cases() {
        let thrown = case.thrown.is_some();
        row(case.name.clone(), &|| {
            methods
                .par_iter()
                .map(|m| contact::run(&case, m).cell(thrown))
                .collect()
        });
    }
    let two = sizes.two;
    row(two.name(), &|| {
        methods.par_iter().map(|m| two.run(m).cell(false)).collect()
    });
}
