// The run filter both passes over the SSIM partials share (loss_partials_horizontal.wgsl along
// rows, loss_gradient.wgsl along columns): the window-weighted sums of the partials for a run of
// LOSS_RUN pixels starting at (x, y) and going along `step`. The including kernel defines
// `partials_input(pixel)`, its source of partials.

// Three vec4 per pixel, as the SSIM partials are stored (loss_per_pixel.wgsl), filtered in
// passes 3 and 4.
struct Partials {
    d_mu: vec4<f32>,
    d_rr: vec4<f32>,
    d_rt: vec4<f32>,
}

fn no_partials() -> Partials {
    return Partials(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
}

fn add_partials(sum: Partials, weight: f32, value: Partials) -> Partials {
    return Partials(sum.d_mu + weight * value.d_mu, sum.d_rr + weight * value.d_rr, sum.d_rt + weight * value.d_rt);
}

struct PartialsRun {
    s0: Partials,
    s1: Partials,
    s2: Partials,
    s3: Partials,
    s4: Partials,
    s5: Partials,
    s6: Partials,
    s7: Partials,
}

// `extent` is the image's size along `step` (width or height), `along` the run's first
// coordinate on that axis, `input_reach` the reach of the pass that wrote the inputs. Inputs
// that pass skipped read as zero (loss_skip.wgsl).
fn filter_partials_run(
    x: i32,
    y: i32,
    step: vec2<i32>,
    along: i32,
    extent: i32,
    input_reach: u32,
) -> PartialsRun {
    let reach = run_reach(x, y, step, along, extent, input_reach);
    var run = PartialsRun(
        no_partials(), no_partials(), no_partials(), no_partials(),
        no_partials(), no_partials(), no_partials(), no_partials(),
    );
    for (var j = 0; j < RUN_INPUTS; j++) {
        let offset = j - WINDOW_RADIUS;
        if along + offset >= 0 && along + offset < extent {
            let source = vec2<i32>(x, y) + offset * step;
            var value = no_partials();
            if input_computed(reach, along + offset) {
                value = partials_input(pixel_index(source.x, source.y));
            }
            run.s0 = add_partials(run.s0, tap_weight(j), value);
            run.s1 = add_partials(run.s1, tap_weight(j - 1), value);
            run.s2 = add_partials(run.s2, tap_weight(j - 2), value);
            run.s3 = add_partials(run.s3, tap_weight(j - 3), value);
            run.s4 = add_partials(run.s4, tap_weight(j - 4), value);
            run.s5 = add_partials(run.s5, tap_weight(j - 5), value);
            run.s6 = add_partials(run.s6, tap_weight(j - 6), value);
            run.s7 = add_partials(run.s7, tap_weight(j - 7), value);
        }
    }
    return run;
}
