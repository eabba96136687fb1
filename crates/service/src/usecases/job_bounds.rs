//! Service-wide ceilings on job configs, checked at submission after the kind's own validation:
//! a config a handler accepts can still ask for more than this deployment will run (4 billion
//! steps, 20 million initial Gaussians that run for minutes before the GPU refuses them).

use crate::config::JobsConfig;
use segsplat_engine::model::max_gaussians_for_binding;
use segsplat_engine::train::budget::MAX_RANDOM_INIT;
use segsplat_gpu::AdapterReport;

/// `Err` names the field, its value and the limit (with its config key).
pub fn check_job_bounds(config: &serde_json::Value, jobs: &JobsConfig) -> Result<(), String> {
    let bounded = [
        ("steps", jobs.max_steps, "jobs.max_steps"),
        ("max_gaussians", jobs.max_gaussians, "jobs.max_gaussians"),
        ("gaussian_budget", jobs.max_gaussians, "jobs.max_gaussians"),
        (
            "random_init_count",
            jobs.max_gaussians,
            "jobs.max_gaussians",
        ),
        ("background_shell", jobs.max_gaussians, "jobs.max_gaussians"),
    ];
    for (field, limit, key) in bounded {
        if let Some(value) = config.get(field).and_then(serde_json::Value::as_u64)
            && value > limit
        {
            return Err(format!(
                "{field}: {value} is over this service's limit of {limit} ({key})"
            ));
        }
    }
    Ok(())
}

/// `Err` when the job's first model (the scene's sparse points, or `random_init_count` random
/// Gaussians when it has none, plus `background_shell`) cannot fit one binding of the smallest
/// of this process's GPU adapters: the job would run until it allocates, then fail. Without
/// adapters here (workers elsewhere) nothing is known and nothing is refused.
pub fn check_adapter_fit(
    config: &serde_json::Value,
    sparse_point_count: u64,
    adapters: &[AdapterReport],
) -> Result<(), String> {
    let Some(smallest) = adapters
        .iter()
        .min_by_key(|adapter| adapter.max_storage_buffer_binding_bytes)
    else {
        return Ok(());
    };
    let field = |name: &str| config.get(name).and_then(serde_json::Value::as_u64);
    let shell = field("background_shell").unwrap_or(0);
    let (source, initial) = if sparse_point_count > 0 {
        ("the scene's sparse points", sparse_point_count)
    } else {
        // Left out, the start is sized from the scene, at most the scene-sized ceiling.
        (
            "random_init_count",
            field("random_init_count").unwrap_or(MAX_RANDOM_INIT as u64),
        )
    };
    let fits = max_gaussians_for_binding(smallest.max_storage_buffer_binding_bytes);
    let needed = initial.saturating_add(shell);
    if needed > fits {
        let field_name = if sparse_point_count > 0 {
            "background_shell"
        } else {
            "random_init_count"
        };
        return Err(format!(
            "{field_name}: {source} ({initial}) plus background_shell ({shell}) make {needed} \
             Gaussians, more than the {fits} that fit GPU adapter {:?} (its storage binding \
             limit is {} bytes)",
            smallest.name, smallest.max_storage_buffer_binding_bytes
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_over_the_limits_are_named() {
        let jobs = JobsConfig::default();
        assert!(check_job_bounds(&serde_json::json!({"steps": 30000}), &jobs).is_ok());
        let error =
            check_job_bounds(&serde_json::json!({"steps": 4_294_967_295u64}), &jobs).unwrap_err();
        assert!(error.starts_with("steps: 4294967295 is over"), "{error}");
        assert!(error.contains("jobs.max_steps"), "{error}");
        let error = check_job_bounds(
            &serde_json::json!({"steps": 10, "random_init_count": 20_000_000}),
            &jobs,
        )
        .unwrap_err();
        assert!(error.starts_with("random_init_count"), "{error}");
    }

    #[test]
    fn first_models_larger_than_the_adapter_binding_are_refused() {
        let adapter = AdapterReport {
            name: "small".to_string(),
            max_storage_buffer_binding_bytes: 60 * 1000,
            ..AdapterReport::default()
        };
        let config = serde_json::json!({"random_init_count": 900, "background_shell": 100});
        assert!(check_adapter_fit(&config, 0, std::slice::from_ref(&adapter)).is_ok());
        let config = serde_json::json!({"random_init_count": 901, "background_shell": 100});
        let error = check_adapter_fit(&config, 0, std::slice::from_ref(&adapter)).unwrap_err();
        assert!(error.starts_with("random_init_count: "), "{error}");
        assert!(error.contains("\"small\""), "{error}");
        assert!(check_adapter_fit(&config, 0, &[]).is_ok());
        let error = check_adapter_fit(&config, 5000, &[adapter]).unwrap_err();
        assert!(error.contains("sparse points (5000)"), "{error}");
    }
}
