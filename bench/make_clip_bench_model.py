#!/usr/bin/python3
"""A CLIP model folder with the shapes and cost of OpenAI's ViT-B/32 and random weights, so bench_mine can
measure embeddings per second with a real-sized model where no CLIP weights can be fetched. Its embeddings
mean nothing; only its speed is measured.

  image: 224 x 224, 32 x 32 patches, width 768, 12 layers, 12 heads, 512-d projection (about 4.4 GFLOPs)
  text:  77 tokens, width 512, 12 layers, 8 heads, 512-d projection, over the tiny test vocabulary (520 ids)
Usage: make_clip_bench_model.py OUT_DIR
"""
import os
import sys

import torch

HERE = os.path.dirname(os.path.realpath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "tools"))
sys.path.insert(0, os.path.join(HERE, "..", "tools", "testing"))
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402
from make_stage_test_models import MERGES, VOCAB  # noqa: E402

SOURCE = "bench/make_clip_bench_model.py (random weights, ViT-B/32 shapes)"


class VisionTower(torch.nn.Module):
    def __init__(self, width=768, layers=12, heads=12, patch=32, size=224, dim=512):
        super().__init__()
        self.patch = torch.nn.Conv2d(3, width, patch, patch, bias=False)
        self.cls = torch.nn.Parameter(torch.randn(1, 1, width) * 0.02)
        self.pos = torch.nn.Parameter(torch.randn(1, (size // patch) ** 2 + 1, width) * 0.01)
        layer = torch.nn.TransformerEncoderLayer(width, heads, 4 * width, 0.0, activation="gelu", batch_first=True,
                                                 norm_first=True)
        self.blocks = torch.nn.TransformerEncoder(layer, layers)
        self.ln = torch.nn.LayerNorm(width)
        self.proj = torch.nn.Linear(width, dim, bias=False)

    def forward(self, image):
        x = self.patch(image).flatten(2).transpose(1, 2)
        x = torch.cat([self.cls.expand(x.shape[0], -1, -1), x], dim=1) + self.pos
        x = self.blocks(x)
        return self.proj(self.ln(x[:, 0]))


class TextTower(torch.nn.Module):
    def __init__(self, vocab=VOCAB, width=512, layers=12, heads=8, context=77, dim=512):
        super().__init__()
        self.tok = torch.nn.Embedding(vocab, width)
        self.pos = torch.nn.Parameter(torch.randn(context, width) * 0.01)
        layer = torch.nn.TransformerEncoderLayer(width, heads, 4 * width, 0.0, activation="gelu", batch_first=True,
                                                 norm_first=True)
        self.blocks = torch.nn.TransformerEncoder(layer, layers)
        self.ln = torch.nn.LayerNorm(width)
        self.proj = torch.nn.Linear(width, dim, bias=False)

    def forward(self, tokens):
        ids = tokens.to(torch.int64)
        x = self.blocks(self.tok(ids) + self.pos)
        x = self.ln(x[torch.arange(x.shape[0]), ids.argmax(dim=-1)])
        return self.proj(x)


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(0)
    save_scripted(VisionTower().eval(), os.path.join(out, "clip_image.pt"),
                  contract("clip_image", "clip-vit-b32-shaped-random",
                           [tensor_spec("image", [-1, 3, 224, 224], (0, 1), "NCHW", "srgb")],
                           [tensor_spec("embedding", [-1, 512], (-1e4, 1e4), "NC")],
                           {"embed_dim": 512, "image_size": 224}, source=SOURCE, license="Apache-2.0"))
    save_scripted(TextTower().eval(), os.path.join(out, "clip_text.pt"),
                  contract("clip_text", "clip-text-b32-shaped-random",
                           [tensor_spec("tokens", [-1, 77], (0, VOCAB - 1), "NL", "token_ids")],
                           [tensor_spec("embedding", [-1, 512], (-1e4, 1e4), "NC")],
                           {"embed_dim": 512, "context_length": 77, "vocab_size": VOCAB}, source=SOURCE,
                           license="Apache-2.0"))
    with open(os.path.join(out, "bpe_simple_vocab_16e6.txt"), "w") as f:
        f.write(MERGES)


if __name__ == "__main__":
    main()
