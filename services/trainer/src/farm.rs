//! `dataset = "farm://HOST:PORT/JOB"`: training on a job's samples straight from its
//! coordinator, while the job is still rendering.
//!
//! A background task follows the job with `StreamSamples` (commit order, from a cursor) and
//! puts every arriving sample into the on-disk [`SampleCache`]; a sample the cache has evicted
//! is fetched again with `GetSample` by the prefetch thread that needs it. Training draws from
//! a *snapshot*: the samples of the split that had arrived when it was taken, ordered by
//! sample index. A snapshot is taken when training starts (after the first sample arrives) and
//! again at every checkpoint, and the snapshot in force is saved in the checkpoint
//! (`stream.json`: cursor and samples). So a resumed run draws exactly the batches an
//! uninterrupted one would have, and every committed sample, old or new, has the same weight
//! once it has joined: new samples wait at most `checkpoint_every` steps.
//!
//! A coordinator outage does not stop training while the samples it needs are cached; when one
//! is not, training pauses with a log line naming the sample and resumes when the coordinator
//! returns.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use lightfarm_proto::client::{channel, transient, AuthedChannel, SampleChunks};
use lightfarm_proto::v1 as pb;
use serde::{Deserialize, Serialize};
use tonic::{Code, Status};

use crate::sample_cache::{SampleCache, SampleRef};
use crate::TrainError;

pub const SCHEME: &str = "farm://";
/// The snapshot in force, saved in every checkpoint of a streamed run.
pub const STREAM_FILE: &str = "stream.json";
/// How long opening waits out an unreachable coordinator before giving up.
const OPEN_PATIENCE: Duration = Duration::from_secs(60);

type Samples = pb::samples_client::SamplesClient<AuthedChannel>;

/// `farm://HOST:PORT/JOB`, parsed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FarmAddress {
    pub host_port: String,
    pub job: String,
}

impl FarmAddress {
    pub fn is_farm(text: &str) -> bool {
        text.starts_with(SCHEME)
    }

    pub fn parse(text: &str) -> Result<FarmAddress, TrainError> {
        let bad = |why: String| {
            TrainError::Config(format!(
                "dataset {text:?}: {why}; write farm://HOST:PORT/JOB with a job id from `lightfarm jobs`"
            ))
        };
        let rest = text
            .strip_prefix(SCHEME)
            .ok_or_else(|| bad("not a farm:// address".into()))?;
        let (host_port, job) = rest
            .split_once('/')
            .ok_or_else(|| bad("no /JOB after the host".into()))?;
        let (host, port) = host_port
            .rsplit_once(':')
            .ok_or_else(|| bad(format!("no :PORT after the host {host_port:?}")))?;
        if host.is_empty() || host.contains(|c: char| c.is_whitespace() || c == '@') {
            return Err(bad(format!("{host:?} is not a host name")));
        }
        if !port.parse::<u16>().is_ok_and(|p| p > 0) {
            return Err(bad(format!("port {port:?} is not a number in 1..=65535")));
        }
        if job.is_empty() || job.contains(|c: char| c == '/' || c.is_whitespace()) {
            return Err(bad(format!("job {job:?} is not a job id")));
        }
        Ok(FarmAddress {
            host_port: host_port.to_owned(),
            job: job.to_owned(),
        })
    }

    /// The coordinator's URL: TLS when a CA is given, as for every other client.
    pub fn url(&self, tls: bool) -> String {
        format!(
            "{}://{}",
            if tls { "https" } else { "http" },
            self.host_port
        )
    }
}

/// The samples a stretch of training draws from, and where the stream stood when they were
/// taken. Saved in checkpoints.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamState {
    pub job: String,
    pub split: String,
    /// `StreamSamples` cursor just past the newest sample of `samples`.
    pub cursor: u64,
    /// Ordered by sample index.
    pub samples: Vec<SampleRef>,
}

impl StreamState {
    pub fn load(checkpoint: &Path) -> Result<Option<StreamState>, TrainError> {
        let path = checkpoint.join(STREAM_FILE);
        match std::fs::read(&path) {
            Ok(bytes) => serde_json::from_slice(&bytes)
                .map(Some)
                .map_err(|e| TrainError::Checkpoint(format!("{}: {e}", path.display()))),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(TrainError::io(&path, e)),
        }
    }
}

pub struct FarmOptions<'a> {
    pub token: &'a str,
    pub tls_ca: Option<&'a Path>,
    pub cache_dir: PathBuf,
    pub cache_bytes: u64,
    /// "train", "test" or "all".
    pub split: &'a str,
    /// The config's crop: the job's images must be at least this big.
    pub crop: usize,
}

#[derive(Default)]
struct Arrived {
    samples: BTreeMap<u64, SampleRef>,
    cursor: u64,
    /// Why following stopped for good (a refused token, a deleted job).
    failed: Option<String>,
}

/// A coordinator job as a dataset.
pub struct FarmSource {
    addr: FarmAddress,
    /// As sent to the coordinator: "" for every split.
    split: String,
    url: String,
    client: Samples,
    cache: Arc<SampleCache>,
    arrived: Arc<Mutex<Arrived>>,
    current: Mutex<Arc<StreamState>>,
    follower: tokio::task::JoinHandle<()>,
    // Last, so the tasks above are dropped with it.
    rt: tokio::runtime::Runtime,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl FarmSource {
    /// Checks the job (it exists, the token is accepted, its images fit the crop), starts
    /// following it, and waits for its first sample of the split, or takes `resume`'s snapshot.
    pub fn open(
        addr: &FarmAddress,
        opts: &FarmOptions<'_>,
        resume: Option<StreamState>,
        cancel: &AtomicBool,
    ) -> Result<FarmSource, TrainError> {
        let url = addr.url(opts.tls_ca.is_some());
        let split = if opts.split == "all" { "" } else { opts.split }.to_owned();
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("farm-stream")
            .enable_all()
            .build()
            .map_err(|e| TrainError::Input(format!("starting the stream runtime: {e}")))?;
        let _entered = rt.enter();
        let (ch, auth) = channel(&url, opts.token, opts.tls_ca).map_err(|e| {
            TrainError::Config(format!(
                "dataset {SCHEME}{}/{}: {e}",
                addr.host_port, addr.job
            ))
        })?;
        let client: Samples =
            pb::samples_client::SamplesClient::with_interceptor(ch.clone(), auth.clone())
                .max_decoding_message_size(64 << 20);
        let jobs = pb::jobs_client::JobsClient::with_interceptor(ch, auth);
        let job = rt.block_on(get_job(jobs, &url, &addr.job, cancel))?;
        check_job(&job, opts.crop)?;
        if let Some(r) = &resume {
            if r.job != addr.job || r.split != split {
                return Err(TrainError::Checkpoint(format!(
                    "this run streamed job {:?} split {:?}; the config now names job {:?} split {:?}: \
                     give it another `out` directory",
                    r.job, r.split, addr.job, split
                )));
            }
        }
        let cache = Arc::new(SampleCache::open(&opts.cache_dir, opts.cache_bytes)?);
        let arrived = Arc::new(Mutex::new(Arrived {
            samples: resume
                .iter()
                .flat_map(|r| r.samples.iter().map(|s| (s.index, s.clone())))
                .collect(),
            cursor: resume.as_ref().map_or(0, |r| r.cursor),
            failed: None,
        }));
        let follower = rt.spawn(follow(
            client.clone(),
            url.clone(),
            addr.job.clone(),
            split.clone(),
            arrived.clone(),
            cache.clone(),
        ));
        let source = FarmSource {
            addr: addr.clone(),
            split: split.clone(),
            url,
            client,
            cache,
            arrived,
            current: Mutex::new(Arc::new(StreamState::default())),
            follower,
            rt,
        };
        let first = match resume {
            Some(r) => r,
            None => source.wait_for_first(cancel)?,
        };
        *lock(&source.current) = Arc::new(first);
        Ok(source)
    }

    fn wait_for_first(&self, cancel: &AtomicBool) -> Result<StreamState, TrainError> {
        let split = self.split.as_str();
        let mut logged = false;
        loop {
            if let Some(s) = self.snapshot()? {
                return Ok(s);
            }
            if cancel.load(Ordering::Relaxed) {
                return Err(TrainError::Input(
                    "stopped while waiting for the first sample".into(),
                ));
            }
            if !logged {
                tracing::info!(
                    job = %self.addr.job,
                    "waiting for the job's first committed sample{}",
                    if split.is_empty() { String::new() } else { format!(" of split {split}") }
                );
                logged = true;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }

    /// Everything that has arrived, if that is more than the current snapshot.
    fn snapshot(&self) -> Result<Option<StreamState>, TrainError> {
        let a = lock(&self.arrived);
        if let Some(why) = &a.failed {
            return Err(TrainError::Input(why.clone()));
        }
        let have = lock(&self.current).samples.len();
        Ok((a.samples.len() > have).then(|| StreamState {
            job: self.addr.job.clone(),
            split: self.split.clone(),
            cursor: a.cursor,
            samples: a.samples.values().cloned().collect(),
        }))
    }

    /// Takes a new snapshot if samples arrived since the last; true if it did.
    pub fn refresh(&self) -> Result<bool, TrainError> {
        let Some(s) = self.snapshot()? else {
            return Ok(false);
        };
        *lock(&self.current) = Arc::new(s);
        Ok(true)
    }

    pub fn state(&self) -> Arc<StreamState> {
        lock(&self.current).clone()
    }

    /// The EXR of sample `index` of the job: from the cache, else from the coordinator,
    /// waiting out an outage.
    pub fn bytes(&self, index: u64) -> Result<Vec<u8>, TrainError> {
        let state = self.state();
        let r = state
            .samples
            .binary_search_by_key(&index, |s| s.index)
            .map(|i| state.samples[i].clone())
            .map_err(|_| {
                TrainError::Input(format!("sample {index} is not in the stream's snapshot"))
            })?;
        if let Some(b) = self.cache.get(&r) {
            return Ok(b);
        }
        let mut wait = Duration::from_millis(250);
        let mut paused: Option<Instant> = None;
        loop {
            match self
                .rt
                .block_on(get_sample(self.client.clone(), &self.addr.job, index))
            {
                Ok((info, data)) => {
                    if let Some(t) = paused {
                        tracing::info!(
                            sample = index,
                            "coordinator back after {:.0} s: training resumes",
                            t.elapsed().as_secs_f64()
                        );
                    }
                    if info.blake3 != r.blake3
                        || data.len() as u64 != r.size
                        || blake3::hash(&data).to_hex().as_str() != r.blake3
                    {
                        return Err(TrainError::Input(format!(
                            "sample {index} of job {} as the coordinator at {} serves it now differs from the one \
                             this run trained on (BLAKE3 {} against {}); train it in a new `out` directory",
                            self.addr.job, self.url, info.blake3, r.blake3
                        )));
                    }
                    self.cache.put(&r, &data);
                    return Ok(data);
                }
                Err(s) if transient(&s) => {
                    if paused.is_none() {
                        tracing::warn!(
                            "training paused: sample {index} of job {} is not cached and the coordinator at {} \
                             is unreachable ({}); retrying until it returns",
                            self.addr.job, self.url, s.message()
                        );
                        paused = Some(Instant::now());
                    }
                    std::thread::sleep(wait);
                    wait = (wait * 2).min(Duration::from_secs(5));
                }
                Err(s) => return Err(refused(&self.url, &self.addr.job, &s)),
            }
        }
    }

    pub fn cache(&self) -> &SampleCache {
        &self.cache
    }
}

impl Drop for FarmSource {
    fn drop(&mut self) {
        self.follower.abort();
    }
}

/// A non-transient refusal, in words that name the fix.
fn refused(url: &str, job: &str, s: &Status) -> TrainError {
    match s.code() {
        Code::Unauthenticated => TrainError::Config(format!(
            "the coordinator at {url} refused the token ({}): pass the coordinator's token with --token or LIGHTFARM_TOKEN",
            s.message()
        )),
        Code::NotFound => TrainError::Config(format!(
            "job {job:?} is not on the coordinator at {url} ({}): `lightfarm jobs` lists its jobs",
            s.message()
        )),
        _ => TrainError::Input(format!("job {job:?} on the coordinator at {url}: {}", s.message())),
    }
}

async fn get_job(
    mut jobs: pb::jobs_client::JobsClient<AuthedChannel>,
    url: &str,
    job: &str,
    cancel: &AtomicBool,
) -> Result<pb::Job, TrainError> {
    let started = Instant::now();
    let mut warned = false;
    loop {
        match jobs.get_job(pb::JobRef { job_id: job.to_owned() }).await {
            Ok(r) => return Ok(r.into_inner()),
            Err(s) if transient(&s) && started.elapsed() < OPEN_PATIENCE && !cancel.load(Ordering::Relaxed) => {
                if !warned {
                    tracing::warn!("coordinator at {url} unreachable ({}); retrying for {} s", s.message(), OPEN_PATIENCE.as_secs());
                    warned = true;
                }
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
            Err(s) if transient(&s) => {
                return Err(TrainError::Config(format!(
                    "cannot reach the coordinator at {url} ({}): is it running, and is farm://HOST:PORT right?",
                    s.message()
                )))
            }
            Err(s) => return Err(refused(url, job, &s)),
        }
    }
}

/// The job's samples must be big enough for the crop; every sample carries the layers the
/// trainer reads (lit0, lit1, albedo, normal, normal_lens, mask), so only the size can miss.
fn check_job(job: &pb::Job, crop: usize) -> Result<(), TrainError> {
    let spec = lightfarm_scene::spec::DatasetSpec::from_toml_str(
        &job.spec_toml,
        format!("job {}", job.id),
    )
    .map_err(|e| {
        TrainError::Config(format!(
            "job {:?}: its spec does not parse here ({e})",
            job.id
        ))
    })?;
    let side = spec.width.min(spec.height).max(0) as usize;
    if crop > side {
        return Err(TrainError::Config(format!(
            "job {:?} renders {}x{} samples; crop = {crop} needs samples at least that big: set `crop` ≤ {side}",
            job.id, spec.width, spec.height
        )));
    }
    Ok(())
}

async fn get_sample(
    mut client: Samples,
    job: &str,
    index: u64,
) -> Result<(pb::SampleInfo, Vec<u8>), Status> {
    let mut stream = client
        .get_sample(pb::GetSampleRequest {
            job_id: job.to_owned(),
            index,
        })
        .await?
        .into_inner();
    let mut chunks = SampleChunks::default();
    while let Some(c) = stream.message().await? {
        chunks.push(c).map_err(Status::internal)?;
    }
    chunks.finish().ok_or_else(|| {
        Status::not_found(format!("the coordinator sent nothing for sample {index}"))
    })
}

/// Follows the job until the source is dropped, reconnecting from the cursor after an outage.
async fn follow(
    client: Samples,
    url: String,
    job: String,
    split: String,
    arrived: Arc<Mutex<Arrived>>,
    cache: Arc<SampleCache>,
) {
    let mut wait = Duration::from_millis(250);
    let mut away: Option<Instant> = None;
    loop {
        let cursor = lock(&arrived).cursor;
        let request = pb::StreamSamplesRequest {
            job_id: job.clone(),
            split: split.clone(),
            cursor,
            follow: true,
            metadata_only: false,
        };
        let status = match client.clone().stream_samples(request).await {
            Ok(response) => {
                if let Some(t) = away.take() {
                    tracing::info!(
                        "coordinator at {url} back after {:.0} s: following job {job} again",
                        t.elapsed().as_secs_f64()
                    );
                }
                wait = Duration::from_millis(250);
                let mut stream = response.into_inner();
                let mut chunks = SampleChunks::default();
                loop {
                    match stream.message().await {
                        Ok(Some(c)) => {
                            if let Err(e) = chunks
                                .push(c)
                                .map(|prev| prev.map(|p| accept(p, &arrived, &cache)))
                            {
                                break Status::internal(e);
                            }
                            if let Some(p) = chunks.take_complete() {
                                accept(p, &arrived, &cache);
                            }
                        }
                        Ok(None) => break Status::unavailable("the sample stream ended"),
                        Err(s) => break s,
                    }
                }
            }
            Err(s) => s,
        };
        if !transient(&status) && status.code() != Code::Internal {
            lock(&arrived).failed = Some(refused(&url, &job, &status).to_string());
            return;
        }
        if away.is_none() {
            tracing::warn!(
                "coordinator at {url} unreachable ({}): training goes on with the samples it has; \
                 new samples of job {job} join when it returns",
                status.message()
            );
            away = Some(Instant::now());
        }
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(Duration::from_secs(5));
    }
}

/// Records an arrived sample; caches it if it is intact (a damaged transfer is fetched again
/// with `GetSample` when drawn).
fn accept((info, data): (pb::SampleInfo, Vec<u8>), arrived: &Mutex<Arrived>, cache: &SampleCache) {
    let r = SampleRef {
        index: info.index,
        blake3: info.blake3,
        size: info.size,
    };
    if data.len() as u64 == r.size && blake3::hash(&data).to_hex().as_str() == r.blake3 {
        cache.put(&r, &data);
    } else {
        tracing::warn!(
            sample = r.index,
            "sample arrived damaged (size or BLAKE3 differs); it will be fetched again"
        );
    }
    let mut a = lock(arrived);
    a.cursor = a.cursor.max(info.sequence + 1);
    a.samples.insert(r.index, r);
}
