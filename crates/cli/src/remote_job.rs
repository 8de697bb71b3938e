//! A job on a trainer service (`lightfarm serve trainer`), followed from the command line:
//! the connection, and a progress bar that follows the job through trainer restarts to its end.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use lightfarm_proto::v1 as pb;

pub(crate) type Client = pb::trainer_client::TrainerClient<lightfarm_worker::client::AuthedChannel>;

/// A client of the trainer at `url`, authenticated with `token`.
pub(crate) fn connect(url: &str, token: Option<String>) -> Result<Client> {
    let token =
        token.context("--token (or LIGHTFARM_TOKEN) is needed to reach a trainer service")?;
    let (ch, auth) = lightfarm_worker::client::channel(url, &token, None)?;
    Ok(pb::trainer_client::TrainerClient::with_interceptor(
        ch, auth,
    ))
}

/// Prints the job's id, then follows it to its end with a progress bar whose message
/// `describe` makes from the newest loss point; an error when the job failed.
pub(crate) async fn follow(
    client: &mut Client,
    job: pb::TrainJob,
    describe: impl Fn(&pb::LossPoint) -> String,
) -> Result<()> {
    println!("{}", job.id);
    let bar = ProgressBar::new(job.steps).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} steps  eta {eta}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut last = job;
    let terminal = |state: i32| {
        [
            pb::TrainJobState::Completed,
            pb::TrainJobState::Failed,
            pb::TrainJobState::Cancelled,
        ]
        .iter()
        .any(|s| *s as i32 == state)
    };
    // A restarting trainer resumes the job; follow it through the restart.
    while !terminal(last.state) {
        let watched = client
            .watch_train_job(pb::TrainJobRef {
                job_id: last.id.clone(),
            })
            .await;
        let mut stream = match watched {
            Ok(s) => s.into_inner(),
            Err(s) if lightfarm_worker::client::transient(&s) => {
                bar.set_message(format!("trainer unreachable ({}); retrying", s.message()));
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
                continue;
            }
            Err(s) => bail!("watching {}: {}", last.id, s.message()),
        };
        loop {
            match stream.message().await {
                Ok(Some(p)) => {
                    if let Some(l) = p.losses.last() {
                        bar.set_message(describe(l));
                    }
                    if let Some(j) = p.job {
                        bar.set_position(j.step);
                        last = j;
                    }
                }
                Ok(None) => break,
                Err(s) if lightfarm_worker::client::transient(&s) => break,
                Err(s) => bail!("watching {}: {}", last.id, s.message()),
            }
        }
    }
    bar.finish();
    match pb::TrainJobState::try_from(last.state) {
        Ok(pb::TrainJobState::Completed) => {
            println!("{} completed at step {}", last.id, last.step);
            Ok(())
        }
        Ok(pb::TrainJobState::Cancelled) => {
            println!("{} cancelled at step {}", last.id, last.step);
            Ok(())
        }
        _ => bail!("{} failed: {}", last.id, last.error),
    }
}
