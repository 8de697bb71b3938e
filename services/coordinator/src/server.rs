//! Opening the coordinator's data directory and serving its gRPC API.

use std::collections::HashMap;
use std::future::Future;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use lightfarm_proto::v1 as pb;
use lightfarm_scene::Catalog;
use lightfarm_store::{BlobStore, DiskBlobStore, SampleIndex, TieredBlobStore, DEFAULT_INLINE_MAX};
use tonic::transport::Server;

use crate::dashboard::preview::Previews;
use crate::dashboard::DashboardConfig;
use crate::durability::GroupSync;
use crate::error::CoordError;
use crate::metrics::Metrics;
use crate::scheduler::Scheduler;
use crate::service::{now_unix, JobsService, SamplesService, Shared, WorkersService};

/// How a coordinator runs; `lightfarm serve coordinator` fills it from flags and env.
#[derive(Clone, Debug)]
pub struct CoordinatorConfig {
    /// sled database and blobs live here; everything survives a restart.
    pub data_dir: PathBuf,
    /// Bearer token every RPC must carry.
    pub token: String,
    pub lease_seconds: f64,
    pub heartbeat_seconds: u32,
    pub max_upload_bytes: u64,
    /// The asset catalog jobs are expanded against; its files are served to workers.
    pub catalog: Catalog,
    /// PEM certificate and key: serve TLS instead of plain HTTP/2.
    pub tls: Option<(PathBuf, PathBuf)>,
}

impl CoordinatorConfig {
    pub fn new(data_dir: PathBuf, token: String, catalog: Catalog) -> Self {
        CoordinatorConfig {
            data_dir,
            token,
            lease_seconds: 60.0,
            heartbeat_seconds: 10,
            max_upload_bytes: 256 << 20,
            catalog,
            tls: None,
        }
    }
}

/// An opened coordinator, ready to serve.
pub struct Coordinator {
    shared: Arc<Shared>,
    data_dir: PathBuf,
    token: String,
    tls: Option<(PathBuf, PathBuf)>,
    /// The group-sync queue and the db it flushes; the flusher task starts in `serve`.
    sync: (
        tokio::sync::mpsc::UnboundedReceiver<tokio::sync::oneshot::Sender<Result<(), String>>>,
        sled::Db,
    ),
}

fn io(path: &std::path::Path, e: impl std::fmt::Display) -> CoordError {
    CoordError::Storage(format!("{}: {e}", path.display()))
}

impl Coordinator {
    /// Opens (or creates) the data directory: the sled db, the blob store, and the catalog's
    /// files imported into the blob store so workers can fetch them by hash.
    pub fn open(config: CoordinatorConfig) -> Result<Coordinator, CoordError> {
        if config.token.is_empty() {
            return Err(CoordError::Invalid(
                "a bearer token is required: pass --token or set LIGHTFARM_TOKEN".into(),
            ));
        }
        std::fs::create_dir_all(&config.data_dir).map_err(|e| io(&config.data_dir, e))?;
        let db_path = config.data_dir.join("db");
        // No background flushes: the group sync flushes after the blobs are synced (see
        // durability.rs), at least once a second.
        let db = sled::Config::new()
            .path(&db_path)
            .flush_every_ms(None)
            .open()
            .map_err(|e| io(&db_path, e))?;
        let disk = DiskBlobStore::open_with(
            &config.data_dir.join("blobs"),
            config.max_upload_bytes.max(1 << 30),
            true,
        )?;
        let blobs: Arc<dyn BlobStore> =
            Arc::new(TieredBlobStore::open(&db, disk, DEFAULT_INLINE_MAX)?);
        let mut assets = HashMap::new();
        for asset in &config.catalog.assets {
            let path = config.catalog.path_of(asset);
            let hash = blobs.put_file(&path)?;
            if hash != asset.blake3 {
                return Err(CoordError::Invalid(format!(
                    "asset {} at {}: file hash {hash} differs from the catalog's {}; run \
                     `lightfarm assets verify`",
                    asset.id,
                    path.display(),
                    asset.blake3
                )));
            }
            let size = blobs.size(&hash)?.unwrap_or(0);
            assets.insert(hash, size);
        }
        let catalog_file = config
            .catalog
            .root
            .join(lightfarm_scene::catalog::CATALOG_FILE);
        let catalog_blake3 = blobs.put_file(&catalog_file)?;
        let size = blobs.size(&catalog_blake3)?.unwrap_or(0);
        assets.insert(catalog_blake3.clone(), size);
        let samples = SampleIndex::open(&db)?;
        let metrics = Metrics::new();
        // The index is the authority on what was committed; a process counter starting at 0
        // would make the total disagree with the data after every restart.
        metrics.committed.inc_by(samples.total_count()?);
        let scheduler = Arc::new(Scheduler::open(
            &db,
            config.catalog.clone(),
            samples,
            config.lease_seconds,
        )?);
        let (durable, sync_rx) = GroupSync::channel();
        let shared = Arc::new(Shared {
            scheduler,
            blobs,
            metrics: Arc::new(metrics),
            max_upload_bytes: config.max_upload_bytes,
            heartbeat_seconds: config.heartbeat_seconds,
            assets,
            catalog_blake3,
            durable,
        });
        Ok(Coordinator {
            shared,
            data_dir: config.data_dir,
            token: config.token,
            tls: config.tls,
            sync: (sync_rx, db),
        })
    }

    pub fn scheduler(&self) -> &Arc<Scheduler> {
        &self.shared.scheduler
    }

    pub fn metrics(&self) -> &Arc<Metrics> {
        &self.shared.metrics
    }

    /// The web dashboard's routes, for [`crate::metrics::serve_metrics`]; its previews are
    /// cached under the data directory's `previews/`.
    pub fn dashboard(&self, cfg: &DashboardConfig) -> Result<axum::Router, CoordError> {
        let previews = Previews::new(self.shared.blobs.clone(), self.data_dir.join("previews"));
        crate::dashboard::router(self.shared.scheduler.clone(), previews, cfg)
    }

    /// The HTTPS configuration of the metrics port: the gRPC certificate and key, if any.
    pub fn metrics_tls(&self) -> Result<Option<tokio_rustls::rustls::ServerConfig>, CoordError> {
        self.tls
            .as_ref()
            .map(|(cert, key)| crate::tls_listener::server_config(cert, key))
            .transpose()
    }

    /// Serves gRPC on `listener` until `shutdown` resolves, expiring leases in the background.
    pub async fn serve(
        self,
        listener: tokio::net::TcpListener,
        shutdown: impl Future<Output = ()> + Send + 'static,
    ) -> Result<(), CoordError> {
        let auth = lightfarm_proto::auth::bearer(&self.token, "coordinator");
        let (sync_rx, db) = self.sync;
        let flusher = tokio::spawn(GroupSync::run(
            sync_rx,
            db.clone(),
            self.shared.blobs.clone(),
        ));
        let shared = self.shared.clone();
        let expiry = tokio::spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_millis(500));
            loop {
                tick.tick().await;
                match shared.scheduler.expire(now_unix()) {
                    Ok(n) => shared.metrics.expired_leases.inc_by(n as u64),
                    Err(e) => tracing::error!("lease expiry: {e}"),
                }
            }
        });
        let mut builder = Server::builder();
        if let Some((cert, key)) = &self.tls {
            let cert = std::fs::read(cert).map_err(|e| io(cert, e))?;
            let key = std::fs::read(key).map_err(|e| io(key, e))?;
            builder = builder
                .tls_config(
                    tonic::transport::ServerTlsConfig::new()
                        .identity(tonic::transport::Identity::from_pem(cert, key)),
                )
                .map_err(|e| CoordError::Invalid(format!("TLS: {e}")))?;
        }
        let result = builder
            .add_service(pb::jobs_server::JobsServer::with_interceptor(
                JobsService(self.shared.clone()),
                auth.clone(),
            ))
            .add_service(pb::workers_server::WorkersServer::with_interceptor(
                WorkersService(self.shared.clone()),
                auth.clone(),
            ))
            .add_service(pb::samples_server::SamplesServer::with_interceptor(
                SamplesService(self.shared.clone()),
                auth,
            ))
            .serve_with_incoming_shutdown(
                tokio_stream::wrappers::TcpListenerStream::new(listener),
                shutdown,
            )
            .await
            .map_err(|e| CoordError::Storage(format!("gRPC server: {e}")));
        expiry.abort();
        flusher.abort();
        let _ = self.shared.blobs.sync();
        let _ = db.flush();
        result
    }
}
