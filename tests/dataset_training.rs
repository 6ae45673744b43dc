//! Training over several datasets at once (`tnd train --data A B`, `model::train_data::DatasetTraining`): the pairs
//! each epoch visits, checked against the datasets' own readers.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use crate::dataset_common;

use dataset_common::{gen_config, run, small_set};

use std::collections::BTreeMap;

use tactile_derender::dataset::{Dataset, GenConfig, SplitName};

/// Training over several datasets (a sensor's recordings, imported one by one) visits every train pair of every
/// dataset exactly once an epoch, with the images each dataset holds; over one dataset it is the order
/// `Dataset::batches` gives.
#[test]
fn training_over_several_datasets_covers_each_pair_once_an_epoch() {
    use tactile_derender::model::train::TrainingData;
    use tactile_derender::model::train_data::DatasetTraining;
    let tmp = tempfile::tempdir().unwrap();
    let set = small_set(&tmp.path().join("set"));
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    run(&a, &set, &gen_config(24), 2);
    run(
        &b,
        &set,
        &GenConfig {
            seed: 9,
            ..gen_config(16)
        },
        2,
    );
    let (da, db) = (Dataset::open(&a).unwrap(), Dataset::open(&b).unwrap());
    let (na, nb) = (da.len(SplitName::Train), db.len(SplitName::Train));
    assert!(na > 0 && nb > 0);
    let (w, h) = da.resolution();
    // Every (dataset, pair) identified by its target image's bytes.
    let key = |img: &[f32]| img.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    let mut want = BTreeMap::new();
    for d in [&da, &db] {
        for i in 0..d.len(SplitName::Train) {
            let p = d.pair(SplitName::Train, i).unwrap();
            *want
                .entry((key(&p.imprint.data), key(&p.target.data)))
                .or_insert(0) += 1;
        }
    }
    let mut both = DatasetTraining::concatenated(vec![&da, &db]);
    assert_eq!(both.len(), na + nb);
    let batches = (na + nb).div_ceil(5);
    let mut got = BTreeMap::new();
    for i in 0..batches {
        let t = both.batch(1, i, 5, 7).unwrap();
        assert_eq!(
            t.n,
            if i + 1 < batches {
                5
            } else {
                (na + nb) - 5 * (batches - 1)
            }
        );
        for j in 0..t.n {
            let img = |v: &[f32]| key(&v[j * w * h..(j + 1) * w * h]);
            *got.entry((img(&t.imprint), img(&t.target))).or_insert(0) += 1;
        }
    }
    assert_eq!(got, want, "each pair of both datasets once");
    assert!(both.batch(1, batches, 5, 7).is_err());
    // One dataset: the pairs in the order of Dataset::batches.
    let mut one = DatasetTraining::new(&da);
    for (i, b) in da.batches(SplitName::Train, 5, 7, 2).enumerate() {
        let b = b.unwrap();
        let t = one.batch(2, i, 5, 7).unwrap();
        assert_eq!((t.imprint, t.target), (b.imprint, b.target));
    }
}
