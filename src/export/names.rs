//! Stable, safe names for URDF links/joints, mesh files and glTF nodes.
//!
//! Why it exists: part names come from users and data sets ("Door #2", "抽屉", "") but end up
//! as XML attribute values and file names. A safe name uses only `[A-Za-z0-9_]`, does not
//! start with a digit, and is unique within the object; the mapping depends only on the
//! names and their order, so re-exporting gives the same names.

/// One safe, unique name per input name, in order.
pub fn safe_unique(names: &[String]) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(names.len());
    for n in names {
        let mut s: String = n
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
            s.insert_str(0, "part_");
        }
        s.truncate(64);
        let base = s.clone();
        let mut k = 2;
        while out.contains(&s) || RESERVED.contains(&s.as_str()) {
            s = format!("{base}_{k}");
            k += 1;
        }
        out.push(s);
    }
    out
}

/// Names we generate for helper links and joints; parts may not take them.
const RESERVED: &[&str] = &["world"];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_safe_unique_and_stable() {
        let input: Vec<String> = ["Door #2", "Door_2", "", "3rd", "body", "body"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let out = safe_unique(&input);
        assert_eq!(
            out,
            ["Door__2", "Door_2", "part_", "part_3rd", "body", "body_2"]
        );
        assert_eq!(out, safe_unique(&input));
    }
}
