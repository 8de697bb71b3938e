//! `Samples`: list committed samples, fetch one, stream them in commit order (following a
//! job that still renders).

use super::*;

pub struct SamplesService(pub Arc<Shared>);

fn sample_chunks(
    blobs: &dyn BlobStore,
    record: &SampleRecord,
    metadata_only: bool,
) -> Result<Vec<pb::SampleChunk>, Status> {
    let mut out = vec![pb::SampleChunk {
        kind: Some(pb::sample_chunk::Kind::Info(record_to_pb(record))),
    }];
    if !metadata_only {
        let bytes = blobs.read(&record.blake3).map_err(store)?;
        out.extend(bytes.chunks(CHUNK).map(|c| pb::SampleChunk {
            kind: Some(pb::sample_chunk::Kind::Data(c.to_vec())),
        }));
    }
    Ok(out)
}

#[tonic::async_trait]
impl pb::samples_server::Samples for SamplesService {
    async fn list_samples(
        &self,
        req: Request<pb::ListSamplesRequest>,
    ) -> Result<Response<pb::ListSamplesResponse>, Status> {
        let req = req.into_inner();
        let limit = if req.limit == 0 {
            1000
        } else {
            req.limit.min(10_000)
        } as usize;
        let (records, total) = self
            .0
            .scheduler
            .samples()
            .list(opt(&req.job_id), opt(&req.split), req.offset, limit)
            .map_err(store)?;
        Ok(Response::new(pb::ListSamplesResponse {
            samples: records.iter().map(record_to_pb).collect(),
            total,
        }))
    }

    type GetSampleStream = BoxStream<pb::SampleChunk>;

    async fn get_sample(
        &self,
        req: Request<pb::GetSampleRequest>,
    ) -> Result<Response<Self::GetSampleStream>, Status> {
        let req = req.into_inner();
        let record = self
            .0
            .scheduler
            .samples()
            .get(&req.job_id, req.index)
            .map_err(store)?
            .ok_or_else(|| {
                Status::not_found(format!(
                    "sample {} of job {} is not committed",
                    req.index, req.job_id
                ))
            })?;
        let chunks = sample_chunks(self.0.blobs.as_ref(), &record, false)?;
        Ok(Response::new(Box::pin(tokio_stream::iter(
            chunks.into_iter().map(Ok),
        ))))
    }

    type StreamSamplesStream = BoxStream<pb::SampleChunk>;

    async fn stream_samples(
        &self,
        req: Request<pb::StreamSamplesRequest>,
    ) -> Result<Response<Self::StreamSamplesStream>, Status> {
        let req = req.into_inner();
        let shared = self.0.clone();
        let mut commits = shared.scheduler.samples().subscribe();
        let (tx, rx) = mpsc::channel(8);
        tokio::spawn(async move {
            let mut cursor = req.cursor;
            loop {
                let batch = match shared.scheduler.samples().since(
                    cursor,
                    opt(&req.job_id),
                    opt(&req.split),
                    64,
                ) {
                    Ok(b) => b,
                    Err(e) => {
                        let _ = tx.send(Err(CoordError::from(e).into())).await;
                        return;
                    }
                };
                for record in &batch {
                    cursor = record.sequence + 1;
                    let chunks =
                        match sample_chunks(shared.blobs.as_ref(), record, req.metadata_only) {
                            Ok(c) => c,
                            Err(e) => {
                                let _ = tx.send(Err(e)).await;
                                return;
                            }
                        };
                    for c in chunks {
                        if tx.send(Ok(c)).await.is_err() {
                            return;
                        }
                    }
                }
                if batch.is_empty() {
                    if !req.follow {
                        return;
                    }
                    if commits.changed().await.is_err() {
                        return;
                    }
                }
            }
        });
        let stream = ReceiverStream::new(rx).map(|x| x);
        Ok(Response::new(Box::pin(stream)))
    }
}
