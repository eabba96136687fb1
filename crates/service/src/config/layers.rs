//! How the layers meet: a TOML table merged over another, and a `SEGSPLAT_*` variable's value
//! put at its key.

pub(super) fn merge_tables(base: &mut toml::Table, overlay: toml::Table) {
    for (key, value) in overlay {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(base_table)), toml::Value::Table(overlay_table)) => {
                merge_tables(base_table, overlay_table);
            }
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

pub(super) fn insert_env_value(
    table: &mut toml::Table,
    segments: &[String],
    raw: &str,
) -> Result<(), String> {
    let Some((last, parents)) = segments.split_last() else {
        return Err("empty key".to_string());
    };
    let mut current = table;
    for segment in parents {
        let entry = current
            .entry(segment.clone())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        current = match entry {
            toml::Value::Table(inner) => inner,
            _ => return Err(format!("{segment} is not a section")),
        };
    }
    current.insert(last.clone(), parse_env_value(raw));
    Ok(())
}

/// A TOML value when the text is one (`5`, `true`, `["a"]`), the text as a string otherwise.
pub(super) fn parse_env_value(raw: &str) -> toml::Value {
    let document = format!("value = {raw}");
    match toml::from_str::<toml::Table>(&document) {
        Ok(mut parsed) => parsed
            .remove("value")
            .unwrap_or_else(|| toml::Value::String(raw.to_string())),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}
