//! `RadixSort` against a CPU stable sort (exact). Values are the original indices, so stability
//! is checked by comparing values too; elements beyond the GPU-read count must stay untouched.

mod gpu_support;

use gpu_support::{gpu_context, new_encoder, seeded_rng, storage_buffer, submit};
use rand::Rng;
use segsplat_gpu::{DEFAULT_SMALL_SORT_LIMIT, GpuContext, RadixSort, WorkgroupSum};

const SENTINEL: u32 = 0x5eed_5eed;

/// Stable CPU sort by the low `key_bits` bits.
fn cpu_stable_sort(keys: &[u32], values: &[u32], key_bits: u32) -> (Vec<u32>, Vec<u32>) {
    let mask = if key_bits >= 32 {
        u32::MAX
    } else {
        (1u32 << key_bits) - 1
    };
    let mut pairs: Vec<(u32, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    pairs.sort_by_key(|&(key, _)| key & mask);
    pairs.into_iter().unzip()
}

struct SortCase {
    keys: Vec<u32>,
    /// Elements the sort may touch; the rest of the buffers holds sentinels.
    count: usize,
    capacity: usize,
    key_bits: u32,
}

/// Random keys with many duplicates in the sorted bits and noise in the ignored high bits.
fn random_keys(rng: &mut impl Rng, count: usize, key_bits: u32, distinct: u32) -> Vec<u32> {
    (0..count)
        .map(|_| {
            let low = if key_bits >= 32 {
                rng.random_range(0..distinct).wrapping_mul(0x9e37_79b9)
            } else {
                rng.random_range(0..distinct) & ((1u32 << key_bits) - 1)
            };
            let high = if key_bits >= 32 {
                0
            } else {
                rng.random::<u32>() << key_bits
            };
            low | high
        })
        .collect()
}

/// Uploads the case (count stored at `count_offset` of a separate buffer), sorts on the GPU and
/// returns keys and values as read back.
fn gpu_sort(
    ctx: &GpuContext,
    sort: &mut RadixSort,
    case: &SortCase,
    count_offset: u64,
) -> (Vec<u32>, Vec<u32>) {
    let mut keys = case.keys.clone();
    keys.resize(case.capacity, SENTINEL);
    let mut values: Vec<u32> = (0..case.count as u32).collect();
    values.resize(case.capacity, SENTINEL);
    let mut count_words = vec![u32::MAX; (count_offset / 4) as usize + 3];
    count_words[(count_offset / 4) as usize] = case.count as u32;
    let keys_buffer = storage_buffer(ctx, "keys", &keys);
    let values_buffer = storage_buffer(ctx, "values", &values);
    let count_buffer = storage_buffer(ctx, "count", &count_words);
    let mut encoder = new_encoder(ctx);
    sort.encode(
        ctx,
        &mut encoder,
        &keys_buffer,
        &values_buffer,
        &count_buffer,
        count_offset,
        case.capacity as u32,
        case.key_bits,
    );
    submit(ctx, encoder);
    (
        ctx.read_vec(&keys_buffer).unwrap(),
        ctx.read_vec(&values_buffer).unwrap(),
    )
}

fn check_case(ctx: &GpuContext, sort: &mut RadixSort, case: &SortCase, count_offset: u64) {
    let (gpu_keys, gpu_values) = gpu_sort(ctx, sort, case, count_offset);
    let indices: Vec<u32> = (0..case.count as u32).collect();
    let (cpu_keys, cpu_values) = cpu_stable_sort(&case.keys, &indices, case.key_bits);
    let label = format!(
        "count {} capacity {} key_bits {}",
        case.count, case.capacity, case.key_bits
    );
    let first_bad =
        (0..case.count).find(|&i| gpu_keys[i] != cpu_keys[i] || gpu_values[i] != cpu_values[i]);
    assert_eq!(
        first_bad,
        None,
        "{label}: first mismatch (index, gpu key, cpu key, gpu value, cpu value) {:?}",
        first_bad.map(|i| (i, gpu_keys[i], cpu_keys[i], gpu_values[i], cpu_values[i]))
    );
    assert!(
        gpu_keys[case.count..].iter().all(|&k| k == SENTINEL)
            && gpu_values[case.count..].iter().all(|&v| v == SENTINEL),
        "{label}: elements beyond the count changed"
    );
}

#[test]
fn sort_matches_cpu_stable_sort_across_counts_and_key_bits() {
    let Some(ctx) = gpu_context() else { return };
    // Every way of summing over a workgroup the adapter has, whichever it picks, and both the
    // multi-block passes (limit 0) and the one-workgroup sort (these capacities are under the
    // default limit).
    let paths = WorkgroupSum::supported(ctx)
        .into_iter()
        .flat_map(|sum| [(sum, 0), (sum, DEFAULT_SMALL_SORT_LIMIT)]);
    for (sum, small_limit) in paths {
        let mut sort = RadixSort::with_sum(ctx, sum)
            .unwrap()
            .with_small_sort_limit(small_limit);
        let mut rng = seeded_rng(3);
        for count in [0usize, 1, 63, 65, 1000, 5000] {
            for key_bits in [4u32, 10, 13, 32] {
                let case = SortCase {
                    keys: random_keys(&mut rng, count, key_bits, 50),
                    count,
                    capacity: count + 37,
                    key_bits,
                };
                check_case(ctx, &mut sort, &case, 0);
            }
        }
    }
}

#[test]
fn one_workgroup_sort_handles_its_limit_and_odd_pass_counts() {
    let Some(ctx) = gpu_context() else { return };
    let mut sort = RadixSort::new(ctx).unwrap();
    let mut rng = seeded_rng(4);
    // 5 bits take two passes, 9 three (an odd count ends with the copy back), 32 eight.
    for key_bits in [5u32, 9, 32] {
        let count = DEFAULT_SMALL_SORT_LIMIT as usize - 5;
        let case = SortCase {
            keys: random_keys(&mut rng, count, key_bits, 700),
            count,
            capacity: DEFAULT_SMALL_SORT_LIMIT as usize,
            key_bits,
        };
        check_case(ctx, &mut sort, &case, 0);
    }
}

#[test]
fn sort_of_a_million_pairs_is_stable_beyond_one_pass_of_blocks() {
    let Some(ctx) = gpu_context() else { return };
    let mut sort = RadixSort::new(ctx).unwrap();
    let mut rng = seeded_rng(5);
    for (key_bits, distinct) in [(4u32, 16u32), (13, 3000), (32, 100_000)] {
        let count = 1_000_003;
        let case = SortCase {
            keys: random_keys(&mut rng, count, key_bits, distinct),
            count,
            capacity: count + 1000,
            key_bits,
        };
        check_case(ctx, &mut sort, &case, 0);
    }
}

#[test]
fn sort_reads_count_at_an_unaligned_offset_and_clamps_to_capacity() {
    let Some(ctx) = gpu_context() else { return };
    for small_limit in [0, DEFAULT_SMALL_SORT_LIMIT] {
        let mut sort = RadixSort::new(ctx)
            .unwrap()
            .with_small_sort_limit(small_limit);
        unaligned_count_and_clamp(ctx, &mut sort);
    }
}

fn unaligned_count_and_clamp(ctx: &GpuContext, sort: &mut RadixSort) {
    let mut rng = seeded_rng(9);
    let case = SortCase {
        keys: random_keys(&mut rng, 3000, 12, 200),
        count: 3000,
        capacity: 4096,
        key_bits: 12,
    };
    // 4 * 301 = 1204 is not a multiple of the 256-byte storage offset alignment.
    check_case(ctx, sort, &case, 4 * 301);

    // A count above the capacity sorts `capacity` elements.
    let keys = random_keys(&mut rng, 2048, 8, 100);
    let keys_buffer = storage_buffer(ctx, "keys", &keys);
    let values_buffer = storage_buffer(ctx, "values", &(0..2048u32).collect::<Vec<_>>());
    let count_buffer = storage_buffer(ctx, "count", &[1_000_000u32]);
    let mut encoder = new_encoder(ctx);
    sort.encode(
        ctx,
        &mut encoder,
        &keys_buffer,
        &values_buffer,
        &count_buffer,
        0,
        1500,
        8,
    );
    submit(ctx, encoder);
    let gpu_keys: Vec<u32> = ctx.read_vec(&keys_buffer).unwrap();
    let gpu_values: Vec<u32> = ctx.read_vec(&values_buffer).unwrap();
    let indices: Vec<u32> = (0..1500).collect();
    let (cpu_keys, cpu_values) = cpu_stable_sort(&keys[..1500], &indices, 8);
    assert_eq!(&gpu_keys[..1500], &cpu_keys[..]);
    assert_eq!(&gpu_values[..1500], &cpu_values[..]);
    assert_eq!(&gpu_keys[1500..], &keys[1500..]);
}

#[test]
fn two_sorts_in_one_encoder_compose_like_depth_then_tile() {
    let Some(ctx) = gpu_context() else { return };
    // Both paths at 20k (over the default small-sort limit, so raised for the second).
    for small_limit in [0, u32::MAX] {
        let mut sort = RadixSort::new(ctx)
            .unwrap()
            .with_small_sort_limit(small_limit);
        depth_then_tile(ctx, &mut sort);
    }
}

fn depth_then_tile(ctx: &GpuContext, sort: &mut RadixSort) {
    let mut rng = seeded_rng(13);
    let count = 20_000usize;
    // First by a 32-bit "depth", then stably by a 10-bit "tile": the result is ordered by
    // (tile, depth, index), which is what the rasterizer needs.
    let depths: Vec<u32> = (0..count).map(|_| rng.random_range(0..5000u32)).collect();
    let tiles: Vec<u32> = (0..count).map(|_| rng.random_range(0..1024u32)).collect();
    let depth_buffer = storage_buffer(ctx, "depth keys", &depths);
    let index_buffer = storage_buffer(ctx, "indices", &(0..count as u32).collect::<Vec<_>>());
    let tile_buffer = storage_buffer(ctx, "tile keys", &vec![0u32; count]);
    let count_buffer = storage_buffer(ctx, "count", &[count as u32]);
    let mut encoder = new_encoder(ctx);
    sort.encode(
        ctx,
        &mut encoder,
        &depth_buffer,
        &index_buffer,
        &count_buffer,
        0,
        count as u32,
        32,
    );
    submit(ctx, encoder);
    // Gather tile ids in depth order on the CPU (the rasterizer does this in a kernel).
    let depth_order: Vec<u32> = ctx.read_vec(&index_buffer).unwrap();
    let tiles_in_depth_order: Vec<u32> = depth_order.iter().map(|&i| tiles[i as usize]).collect();
    ctx.queue
        .write_buffer(&tile_buffer, 0, bytemuck::cast_slice(&tiles_in_depth_order));
    let mut encoder = new_encoder(ctx);
    sort.encode(
        ctx,
        &mut encoder,
        &tile_buffer,
        &index_buffer,
        &count_buffer,
        0,
        count as u32,
        10,
    );
    submit(ctx, encoder);
    let final_order: Vec<u32> = ctx.read_vec(&index_buffer).unwrap();
    let mut expected: Vec<u32> = (0..count as u32).collect();
    expected.sort_by_key(|&i| (tiles[i as usize], depths[i as usize], i));
    assert_eq!(final_order, expected);
}

#[test]
fn independent_sorts_recorded_in_one_encoder_both_complete() {
    let Some(ctx) = gpu_context() else { return };
    let mut sort = RadixSort::new(ctx).unwrap();
    let mut rng = seeded_rng(17);
    let cases = [
        SortCase {
            keys: random_keys(&mut rng, 70_000, 32, 1000),
            count: 70_000,
            capacity: 70_000,
            key_bits: 32,
        },
        SortCase {
            keys: random_keys(&mut rng, 9_000, 9, 300),
            count: 9_000,
            capacity: 10_000,
            key_bits: 9,
        },
    ];
    let mut encoder = new_encoder(ctx);
    let mut buffers = Vec::new();
    for case in &cases {
        let mut keys = case.keys.clone();
        keys.resize(case.capacity, SENTINEL);
        let keys_buffer = storage_buffer(ctx, "keys", &keys);
        let values_buffer = storage_buffer(
            ctx,
            "values",
            &(0..case.capacity as u32).collect::<Vec<_>>(),
        );
        let count_buffer = storage_buffer(ctx, "count", &[case.count as u32]);
        sort.encode(
            ctx,
            &mut encoder,
            &keys_buffer,
            &values_buffer,
            &count_buffer,
            0,
            case.capacity as u32,
            case.key_bits,
        );
        buffers.push((keys_buffer, values_buffer));
    }
    submit(ctx, encoder);
    for (case, (keys_buffer, values_buffer)) in cases.iter().zip(&buffers) {
        let indices: Vec<u32> = (0..case.count as u32).collect();
        let (cpu_keys, cpu_values) = cpu_stable_sort(&case.keys, &indices, case.key_bits);
        let gpu_keys: Vec<u32> = ctx.read_vec(keys_buffer).unwrap();
        let gpu_values: Vec<u32> = ctx.read_vec(values_buffer).unwrap();
        assert_eq!(
            &gpu_keys[..case.count],
            &cpu_keys[..],
            "key_bits {}",
            case.key_bits
        );
        assert_eq!(
            &gpu_values[..case.count],
            &cpu_values[..],
            "key_bits {}",
            case.key_bits
        );
    }
}
