"""Submit a dataset spec and train a toy PyTorch model on its samples as they render.
Usage: python train_toy.py ADDRESS TOKEN SPEC.toml"""
import sys

import torch
import lightfarm
from lightfarm.torch import StreamingDataset

address, token, spec = sys.argv[1:4]
job = lightfarm.Client(address, token).submit(spec)       # the farm starts rendering
data = StreamingDataset(address, job.id, token, split="", passes=["lit0", "normal", "mask"])
net = torch.nn.Conv2d(3, 3, 3, padding=1)                 # a toy normal predictor
opt = torch.optim.Adam(net.parameters(), 1e-3)
for batch in torch.utils.data.DataLoader(data, batch_size=2, num_workers=2):
    loss = ((net(batch["lit0"]) - batch["normal"]) ** 2 * batch["mask"]).mean()
    opt.zero_grad(); loss.backward(); opt.step()
    print(f"samples {batch['index'].tolist()}: loss {loss.item():.4f}", flush=True)
