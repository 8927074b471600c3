//! The fixed variants of a sweep: what each one changes.

use super::*;

/// The input variants: what each does to the log before matching.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InputVariant {
    /// `scans/2`: every second record.
    EveryOtherRecord,
    /// `beams/2`: every second beam of every scan.
    EveryOtherBeam,
    /// `odom-noise`: random odometry drift.
    OdometryNoise,
    /// `odom-bias`: systematic odometry drift.
    OdometryBias,
    /// `range-noise`: Gaussian noise on the valid ranges.
    RangeNoise,
    /// `max-range-10`: returns beyond 10 m dropped.
    MaxRange10,
}

impl InputVariant {
    /// Every input variant, in report order.
    pub const ALL: [InputVariant; 6] = [
        InputVariant::EveryOtherRecord,
        InputVariant::EveryOtherBeam,
        InputVariant::OdometryNoise,
        InputVariant::OdometryBias,
        InputVariant::RangeNoise,
        InputVariant::MaxRange10,
    ];

    /// The variant's name on the command line and in reports.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            InputVariant::EveryOtherRecord => "scans/2",
            InputVariant::EveryOtherBeam => "beams/2",
            InputVariant::OdometryNoise => "odom-noise",
            InputVariant::OdometryBias => "odom-bias",
            InputVariant::RangeNoise => "range-noise",
            InputVariant::MaxRange10 => "max-range-10",
        }
    }

    /// The records of a whole log perturbed (the random variants draw from a generator
    /// seeded with [`SEED`], so the result is always the same). Sweeps stream instead
    /// ([`InputVariant::stream`]); this is its brute-force twin, which the tests compare it
    /// with.
    pub fn apply(self, records: &[Record]) -> Result<Vec<Record>> {
        let mut rng = ChaCha8Rng::seed_from_u64(SEED);
        let scans = |f: &mut dyn FnMut(&Scan) -> Result<Scan, ScanError>| {
            records
                .iter()
                .map(|r| {
                    let mut out = r.clone();
                    out.scan = f(&r.scan)
                        .with_context(|| format!("{}: scan at {} s", self.name(), r.timestamp()))?;
                    Ok(out)
                })
                .collect::<Result<Vec<_>>>()
        };
        match self {
            InputVariant::EveryOtherRecord => Ok(every_other_record(records)),
            InputVariant::EveryOtherBeam => scans(&mut every_other_beam),
            InputVariant::OdometryNoise => Ok(with_odometry_increments(records, |d| {
                noisy_increment(d, &mut rng)
            })),
            InputVariant::OdometryBias => Ok(with_odometry_increments(records, biased_increment)),
            InputVariant::RangeNoise => {
                scans(&mut |s| noisy_ranges(s, RANGE_NOISE_SIGMA, &mut rng))
            }
            InputVariant::MaxRange10 => scans(&mut |s| capped_range(s, CAPPED_MAX_RANGE)),
        }
    }

    /// The records of a stream perturbed one at a time, as [`InputVariant::apply`] perturbs a
    /// whole log: the same records, drawn from the same seeded generator in the same order.
    pub fn stream<I: Iterator<Item = Result<Record>>>(self, records: I) -> Perturbed<I> {
        Perturbed {
            records,
            variant: self,
            rng: ChaCha8Rng::seed_from_u64(SEED),
            read: 0,
            odometry: None,
        }
    }
}

/// A stream of records under an [`InputVariant`] ([`InputVariant::stream`]).
#[derive(Debug)]
pub struct Perturbed<I> {
    records: I,
    variant: InputVariant,
    rng: ChaCha8Rng,
    /// Records read so far.
    read: usize,
    /// The last raw odometry and what replaced it (odometry variants).
    odometry: Option<(Pose2, Pose2)>,
}

impl<I> Perturbed<I> {
    /// The odometry replacing `raw`: the last replacement composed with the raw increment
    /// passed through `perturb`, as [`perturb_increments`] recomposes a whole log.
    fn drifted(
        &mut self,
        raw: Pose2,
        perturb: impl FnOnce(Pose2, &mut ChaCha8Rng) -> Pose2,
    ) -> Pose2 {
        let out = match self.odometry {
            Some((last_raw, last_out)) => {
                last_out.compose(&perturb(last_raw.between(&raw), &mut self.rng))
            }
            None => raw,
        };
        self.odometry = Some((raw, out));
        out
    }
}

impl<I: Iterator<Item = Result<Record>>> Iterator for Perturbed<I> {
    type Item = Result<Record>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let mut record = match self.records.next()? {
                Ok(r) => r,
                Err(e) => return Some(Err(e)),
            };
            let index = self.read;
            self.read += 1;
            let name = self.variant.name();
            let scan = match self.variant {
                InputVariant::EveryOtherRecord if index % 2 == 1 => continue,
                InputVariant::EveryOtherRecord => Ok(None),
                InputVariant::EveryOtherBeam => every_other_beam(&record.scan).map(Some),
                InputVariant::RangeNoise => {
                    noisy_ranges(&record.scan, RANGE_NOISE_SIGMA, &mut self.rng).map(Some)
                }
                InputVariant::MaxRange10 => capped_range(&record.scan, CAPPED_MAX_RANGE).map(Some),
                InputVariant::OdometryNoise => {
                    record.odometry = self.drifted(record.odometry, noisy_increment);
                    Ok(None)
                }
                InputVariant::OdometryBias => {
                    record.odometry = self.drifted(record.odometry, |d, _| biased_increment(d));
                    Ok(None)
                }
            };
            match scan {
                Ok(Some(scan)) => record.scan = scan,
                Ok(None) => {}
                Err(e) => {
                    return Some(Err(anyhow::Error::from(e)
                        .context(format!("{name}: scan at {} s", record.timestamp()))));
                }
            }
            return Some(Ok(record));
        }
    }
}

/// What a variant changes.
#[derive(Debug, Clone, PartialEq)]
pub enum Perturbation {
    /// The input.
    Input(InputVariant),
    /// One parameter of the configuration, scaled.
    Parameter {
        /// Dotted key, as [`MatcherConfig::steering_parameters`] gives it.
        key: String,
        /// The factor.
        factor: f64,
    },
}

/// One variant of the sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Variant {
    /// Its name: `scans/2`, `icp.max_dist_start*0.7`…
    pub name: String,
    /// What it changes.
    pub perturbation: Perturbation,
}

/// Every variant for `config`, in report order: the input variants, then each steering
/// parameter times each of [`PARAMETER_FACTORS`]. A parameter variant is named by its key
/// without the leading `matcher.`, a `*` and the factor: `icp.max_dist_start*0.7`.
#[must_use]
pub fn all_variants(config: &MatcherConfig) -> Vec<Variant> {
    let inputs = InputVariant::ALL.into_iter().map(|v| Variant {
        name: v.name().to_string(),
        perturbation: Perturbation::Input(v),
    });
    let parameters = config.steering_parameters().into_iter().flat_map(|key| {
        PARAMETER_FACTORS.into_iter().map(move |factor| {
            let short = key.strip_prefix("matcher.").unwrap_or(&key);
            Variant {
                name: format!("{short}*{factor}"),
                perturbation: Perturbation::Parameter {
                    key: key.clone(),
                    factor,
                },
            }
        })
    });
    inputs.chain(parameters).collect()
}

/// Parameters whose variants were named after another section once: `(old, new)`. The laser
/// noise was WSM's own parameter (`[matcher.wsm] sigma_range`, still read from old configs)
/// before it became the sensor's (`[matcher.laser]`).
pub const RENAMED_PARAMETERS: &[(&str, &str)] = &[("wsm.sigma_range", "laser.sigma_range")];

/// The current name of a variant given by an old name (see [`RENAMED_PARAMETERS`]), e.g.
/// `wsm.sigma_range*0.7` → `laser.sigma_range*0.7`; other names as they are.
#[must_use]
pub fn current_name(name: &str) -> String {
    for (old, new) in RENAMED_PARAMETERS {
        if let Some(factor) = name.strip_prefix(old).filter(|f| f.starts_with('*')) {
            return format!("{new}{factor}");
        }
    }
    name.to_string()
}

/// The variants named in `names` (in report order, each once); `default` is accepted and
/// ignored, since the default run always happens. An unknown name is an error listing the
/// known ones.
pub fn select_variants(all: Vec<Variant>, names: &[String]) -> Result<Vec<Variant>> {
    // (as given, current name)
    let given: Vec<(&str, String)> = names
        .iter()
        .map(|n| (n.trim(), current_name(n.trim())))
        .filter(|(n, _)| !n.is_empty() && *n != "default")
        .collect();
    let names: Vec<&str> = given.iter().map(|(_, n)| n.as_str()).collect();
    // An unknown name is reported as the user gave it.
    let unknown: Vec<&str> = given
        .iter()
        .filter(|(_, n)| !all.iter().any(|v| v.name == *n))
        .map(|(g, _)| *g)
        .collect();
    if !unknown.is_empty() {
        let known: Vec<&str> = all.iter().map(|v| v.name.as_str()).collect();
        bail!(
            "unknown variant{} {}; known: {}",
            if unknown.len() > 1 { "s" } else { "" },
            unknown.join(", "),
            known.join(", ")
        );
    }
    Ok(all
        .into_iter()
        .filter(|v| names.contains(&v.name.as_str()))
        .collect())
}
