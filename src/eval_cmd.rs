//! `qicp eval …`: the metrics of `qicp-eval` on files, as tables or JSON.

use crate::eval::*;
use crate::logs::relations::read_relations;
use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use std::path::PathBuf;

// ---------------------------------------------------------------------------------------------
// CLI

/// Evaluations.
#[derive(Debug, Subcommand)]
pub enum EvalCommand {
    /// Score a trajectory with Freiburg benchmark relations (Kümmerle et al. 2009).
    Relations(RelationsArgs),
    /// Compare a trajectory with ground truth: ATE after origin alignment, RPE per metre,
    /// final error.
    Ate(AteArgs),
}

/// Arguments of `qicp eval relations`.
#[derive(Debug, Args)]
pub struct RelationsArgs {
    /// The trajectory: TUM file, or CARMEN log (its laser records' odometry is scored).
    pub traj: PathBuf,
    /// The `.relations` file (`t1 t2 x y z roll pitch yaw` per line).
    pub relations: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Association window (s) between relation and trajectory timestamps.
    #[arg(long, default_value_t = DEFAULT_MAX_DT)]
    pub max_dt: f64,
}

/// Arguments of `qicp eval ate`.
#[derive(Debug, Args)]
pub struct AteArgs {
    /// The estimate: TUM file, or CARMEN log (its laser records' odometry).
    pub est: PathBuf,
    /// The ground truth: TUM file, or CARMEN log (its `TRUEPOS` at the laser records).
    pub truth: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Association window (s) between estimate and truth timestamps.
    #[arg(long, default_value_t = DEFAULT_MAX_DT)]
    pub max_dt: f64,
    /// Segment length (m) of the relative pose error.
    #[arg(long, default_value_t = DEFAULT_RPE_SEGMENT_M)]
    pub rpe_segment: f64,
}

/// Runs the command.
pub fn run(c: EvalCommand) -> Result<()> {
    match c {
        EvalCommand::Relations(a) => {
            let traj = load_trajectory(&a.traj, LogPoses::Odometry)?;
            let rels = read_relations(&a.relations)?;
            if rels.is_empty() {
                anyhow::bail!("{} holds no relations", a.relations.display());
            }
            let r = evaluate_relations(&traj, &rels, a.max_dt)
                .with_context(|| format!("scoring {}", a.traj.display()))?;
            // The JSON stands whatever it holds (a script reads `n`); a table of nothing
            // scored would only print NaNs above the error.
            if a.json {
                qicp_core::say!("{}", serde_json::to_string_pretty(&r)?)?;
            } else if r.n > 0 {
                qicp_core::say!("{}", relations_table(&r))?;
            }
            if r.n == 0 {
                anyhow::bail!(
                    "no relation of {} has poses within {} s in {} ({} relations): is it the \
                     trajectory's relations file?",
                    a.relations.display(),
                    a.max_dt,
                    a.traj.display(),
                    rels.len()
                );
            }
        }
        EvalCommand::Ate(a) => {
            let est = load_trajectory(&a.est, LogPoses::Odometry)?;
            let truth = load_trajectory(&a.truth, LogPoses::Truth)?;
            let opts = AteOptions {
                max_dt: a.max_dt,
                rpe_segment_m: a.rpe_segment,
            };
            let r = evaluate_ate(&est, &truth, &opts).with_context(|| {
                format!("comparing {} with {}", a.est.display(), a.truth.display())
            })?;
            if a.json {
                qicp_core::say!("{}", serde_json::to_string_pretty(&r)?)?;
            } else {
                qicp_core::say!("{}", ate_table(&r))?;
            }
        }
    }
    Ok(())
}

fn relations_table(r: &RelationsReport) -> String {
    format!(
        "relations evaluated   {}\n\
         relations missing     {}\n\
         translational error   {:.4} ± {:.4} m (max {:.4} m)\n\
         rotational error      {:.3} ± {:.3}° (max {:.3}°)",
        r.n,
        r.missing,
        r.trans_mean,
        r.trans_std,
        r.trans_max,
        r.rot_mean_deg,
        r.rot_std_deg,
        r.rot_max_deg
    )
}

fn ate_table(r: &AteReport) -> String {
    format!(
        "pose pairs            {} ({} unpaired)\n\
         ATE RMSE              {:.4} m (mean {:.4} m, max {:.4} m)\n\
         RPE per {} m          {:.3} % translation, {:.4}°/m rotation ({} segments)\n\
         final error           {:.4} m, {:.3}° after {:.2} m",
        r.n,
        r.missing,
        r.ate_rmse_m,
        r.ate_mean_m,
        r.ate_max_m,
        r.rpe_segment_m,
        r.rpe_trans_per_m * 100.0,
        r.rpe_rot_deg_per_m,
        r.rpe_segments,
        r.final_error_m,
        r.final_heading_error_deg,
        r.path_length_m
    )
}
