#!/usr/bin/python3
"""Builds the tiny TorchScript models the C++ tests of the CLIP, normal-estimation, LRM and harmonisation
stages run (python3-torch; no weights needed).

Each model honours its SynthDrive stage contract with a small, analytic computation, so the C++ tests can
predict its outputs exactly: the tensor layouts, ranges, batching, padding, chunking and the classical
post-processing are checked end to end without real weights.
Usage: make_stage_test_models.py OUT_DIR
"""
import json
import os
import re
import sys

import torch

from raw_tensors import write_raw  # noqa: E402  (beside this script)
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

SOURCE = "tools/testing/make_stage_test_models.py"
LICENSE = "Apache-2.0"

# The handmade BPE merges of src/models/clip_tokenizer_test.cpp: vocabulary 512 + 6 + 2 = 520.
MERGES = "#version: 0.2\nh e\nl l\nhe ll\nhell o</w>\nw o\nr l\n"
VOCAB = 520
# "hello world" under MERGES, worked out by hand in clip_tokenizer_test.cpp: start, hello</w>, wo, rl, d</w>, end.
HELLO_WORLD_IDS = [518, 515, 516, 517, 256 + ord("d") - 33, 519]


# --- CLIP -------------------------------------------------------------------------------------------------

class TinyClipImage(torch.nn.Module):
    """Normalisation inside the module (as the exporter bakes it in), 4x4 average pool, linear to D."""

    def __init__(self, dim: int):
        super().__init__()
        self.register_buffer("mean", torch.tensor([0.48145466, 0.4578275, 0.40821073]).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor([0.26862954, 0.26130258, 0.27577711]).view(1, 3, 1, 1))
        self.proj = torch.nn.Linear(48, dim)

    def forward(self, image):
        x = (image - self.mean) / self.std
        return self.proj(F.adaptive_avg_pool2d(x, 4).flatten(1))


class TinyClipText(torch.nn.Module):
    """Token embedding + position, features at the end token (the highest id, as CLIP picks it) plus the mean."""

    def __init__(self, vocab: int, dim: int, context: int):
        super().__init__()
        self.tok = torch.nn.Embedding(vocab, dim)
        self.pos = torch.nn.Parameter(0.1 * torch.randn(context, dim))
        self.proj = torch.nn.Linear(dim, dim)

    def forward(self, tokens):
        ids = tokens.to(torch.int64)  # float32 carries exact integers across the runtime; back to indices here
        x = self.tok(ids) + self.pos
        end = ids.argmax(dim=-1)
        f = x[torch.arange(x.shape[0]), end]
        return self.proj(f + x.mean(dim=1))


def make_clip(out):
    dim, ctx, size = 16, 77, 224
    d = os.path.join(out, "clip_tiny")
    os.makedirs(d, exist_ok=True)
    image, text = TinyClipImage(dim).eval(), TinyClipText(VOCAB, dim, ctx).eval()
    params_i = {"embed_dim": dim, "image_size": size}
    params_t = {"embed_dim": dim, "context_length": ctx, "vocab_size": VOCAB}
    embedding = tensor_spec("embedding", [-1, dim], (-1e4, 1e4), "NC")
    save_scripted(image, os.path.join(d, "clip_image.pt"),
                  contract("clip_image", "clip-tiny-image",
                           [tensor_spec("image", [-1, 3, size, size], (0, 1), "NCHW", "srgb")], [embedding],
                           params_i, SOURCE, LICENSE))
    save_scripted(text, os.path.join(d, "clip_text.pt"),
                  contract("clip_text", "clip-tiny-text",
                           [tensor_spec("tokens", [-1, ctx], (0, VOCAB - 1), "NL", "token_ids")], [dict(embedding)],
                           params_t, SOURCE, LICENSE))
    with open(os.path.join(d, "bpe_simple_vocab_16e6.txt"), "w") as f:
        f.write(MERGES)
    # References from the eager modules: an image already at 224 (no resize) and the ids of "hello world".
    x = torch.rand(1, 3, size, size)
    ids = torch.zeros(1, ctx)
    ids[0, :len(HELLO_WORLD_IDS)] = torch.tensor(HELLO_WORLD_IDS, dtype=torch.float32)
    with torch.no_grad():
        ei, et = F.normalize(image(x), dim=1), F.normalize(text(ids), dim=1)
    write_raw(os.path.join(out, "clip_image_input.f32"), x)
    write_raw(os.path.join(out, "clip_image_embedding.f32"), ei)
    write_raw(os.path.join(out, "clip_text_hello_world.f32"), et)


# --- normal estimation -------------------------------------------------------------------------------------

class TinyNormals(torch.nn.Module):
    """Per pixel (2r - 1, 2g - 1, -1 - b) times 3 (not unit: the C++ side renormalises); refuses sizes that are
    not multiples of 8, as patch-based estimators do."""

    def forward(self, image):
        if image.shape[2] % 8 != 0 or image.shape[3] % 8 != 0:
            raise RuntimeError("height and width must be multiples of 8")
        n = torch.stack([2 * image[:, 0] - 1, 2 * image[:, 1] - 1, -1 - image[:, 2]], dim=1)
        return 3.0 * n


def make_normals(out):
    img = tensor_spec("image", [-1, 3, -1, -1], (0, 1), "NCHW", "srgb")
    normals = tensor_spec("normals", [-1, 3, -1, -1], (-1, 1), "NCHW", "camera_opencv")
    save_scripted(TinyNormals(), os.path.join(out, "normals_tiny.pt"),
                  contract("normal_estimation", "normals-tiny", [img], [normals], {"multiple": 8}, SOURCE, LICENSE))


# --- LRM ----------------------------------------------------------------------------------------------------

class TinyLrmEncoder(torch.nn.Module):
    """Triplane [1, 3, 4, 8, 8] filled with the image's mean colour (channels 0..2) and mean grey (channel 3)."""

    def forward(self, image):
        m = image.mean(dim=(2, 3))
        feats = torch.cat([m, m.mean(dim=1, keepdim=True)], dim=1)
        return feats[:, None, :, None, None].expand(1, 3, 4, 8, 8).contiguous()


class TinyLrmDecoder(torch.nn.Module):
    """A sphere at the origin of radius 0.15 + 0.2 * grey (the signed distance, negative inside), coloured with
    the mean colour."""

    def forward(self, triplane, points):
        feats = triplane.mean(dim=(1, 3, 4))
        radius = 0.15 + 0.2 * feats[:, 3]
        sdf = torch.sqrt((points * points).sum(dim=-1, keepdim=True)) - radius[:, None, None]
        colour = feats[:, None, 0:3].expand(points.shape[0], points.shape[1], 3)
        return sdf, colour


def make_lrm(out):
    image = tensor_spec("image", [1, 3, 32, 32], (0, 1), "NCHW", "srgb")
    triplane = tensor_spec("triplane", [1, 3, 4, 8, 8], (-1e4, 1e4), "NPCHW")
    points = tensor_spec("points", [1, -1, 3], (-0.5, 0.5), "NPC", "unit_cube")
    sdf = tensor_spec("sdf", [1, -1, 1], (-1e4, 1e4), "NPC")
    colour = tensor_spec("colour", [1, -1, 3], (0, 1), "NPC", "srgb")
    params = {"image_size": 32, "triplane_channels": 4, "triplane_resolution": 8}
    save_scripted(TinyLrmEncoder(), os.path.join(out, "lrm_tiny_encoder.pt"),
                  contract("lrm_encoder", "lrm-tiny-encoder", [image], [triplane], params, SOURCE, LICENSE))
    save_scripted(TinyLrmDecoder(), os.path.join(out, "lrm_tiny_decoder.pt"),
                  contract("lrm_decoder", "lrm-tiny-decoder", [dict(triplane), points], [sdf, colour], params, SOURCE,
                           LICENSE))
    # The same decoder as a trace frozen at 1000 points would declare itself.
    fixed = [dict(triplane), dict(points, shape=[1, 1000, 3])]
    save_scripted(TinyLrmDecoder(), os.path.join(out, "lrm_tiny_decoder_p1000.pt"),
                  contract("lrm_decoder", "lrm-tiny-decoder-p1000", fixed,
                           [dict(sdf, shape=[1, 1000, 1]), dict(colour, shape=[1, 1000, 3])], params, SOURCE, LICENSE))


# --- harmonisation ------------------------------------------------------------------------------------------

class TinyHarmonizer(torch.nn.Module):
    """Inside the mask: 0.5 * composite + 0.25; outside it adds 0.1, which the C++ side must not keep (it blends
    the model's output in by the mask)."""

    def forward(self, composite, mask):
        return mask * (0.5 * composite + 0.25) + (1 - mask) * (composite + 0.1)


def make_harmonizer(out):
    comp = tensor_spec("composite", [-1, 3, -1, -1], (0, 1), "NCHW", "srgb")
    mask = tensor_spec("mask", [-1, 1, -1, -1], (0, 1), "NCHW")
    res = tensor_spec("image", [-1, 3, -1, -1], (0, 1), "NCHW", "srgb")
    save_scripted(TinyHarmonizer(), os.path.join(out, "harmonizer_tiny.pt"),
                  contract("harmonization", "harmonizer-tiny", [comp, mask], [res], {}, SOURCE, LICENSE))
    save_scripted(TinyHarmonizer(), os.path.join(out, "harmonizer_tiny_64.pt"),
                  contract("harmonization", "harmonizer-tiny-64", [comp, mask], [res], {"image_size": 64}, SOURCE,
                           LICENSE))


# --- an independent tokenizer reference -------------------------------------------------------------------
# The reference CLIP tokenizer, restated in Python from its description (not from the C++), on merges learned
# here by plain BPE training over a small corpus, so the C++ tokenizer meets realistic merge chains. Python's
# re has no \p{L}: letters are [^\W\d_], digits \d, the rest [^\s\w]|_ ; the cases stay in ASCII and Latin-1
# where those classes equal the Unicode ones.

def byte_symbols():
    printable = list(range(ord("!"), ord("~") + 1)) + list(range(0xA1, 0xAD)) + list(range(0xAE, 0x100))
    order, codes, n = list(printable), list(printable), 0
    for b in range(256):
        if b not in printable:
            order.append(b)
            codes.append(256 + n)
            n += 1
    return {b: chr(c) for b, c in zip(order, codes)}, order


PIECES = re.compile(r"<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[^\W\d_]+|\d|(?:[^\s\w]|_)+")
CORPUS = ("a photo of a red car parked on the street next to a white van. the cars are parked; "
          "pedestrians cross the road while a cyclist waits. it's a sunny day, isn't it? "
          "traffic cones, barriers and a construction truck block the right lane. "
          "the bus stops at the station and the passengers get off. trucks carry cargo on the highway. ") * 3


def train_merges(count):
    enc, _ = byte_symbols()
    words = {}
    for w in re.findall(r"[a-z]+|[^\sa-z]", CORPUS):
        sym = tuple(enc[b] for b in w.encode("utf-8"))
        sym = sym[:-1] + (sym[-1] + "</w>",)
        words[sym] = words.get(sym, 0) + 1
    merges = []
    for _ in range(count):
        pairs = {}
        for w, f in words.items():
            for a, b in zip(w, w[1:]):
                pairs[(a, b)] = pairs.get((a, b), 0) + f
        if not pairs:
            break
        best = max(sorted(pairs), key=lambda p: pairs[p])
        merges.append(best)
        new = {}
        for w, f in words.items():
            out, i = [], 0
            while i < len(w):
                if i + 1 < len(w) and (w[i], w[i + 1]) == best:
                    out.append(w[i] + w[i + 1])
                    i += 2
                else:
                    out.append(w[i])
                    i += 1
            new[tuple(out)] = new.get(tuple(out), 0) + f
        words = new
    return merges


def reference_tokenize(text, merges, context=77):
    enc, order = byte_symbols()
    vocab = [enc[b] for b in order]
    vocab += [v + "</w>" for v in vocab] + ["".join(m) for m in merges] + ["<|startoftext|>", "<|endoftext|>"]
    ids = {v: i for i, v in enumerate(vocab)}
    ranks = {m: i for i, m in enumerate(merges)}
    text = " ".join(text.split()).lower()
    out = [ids["<|startoftext|>"]]
    for piece in PIECES.findall(text):
        if piece in ("<|startoftext|>", "<|endoftext|>"):
            out.append(ids[piece])
            continue
        word = [enc[b] for b in piece.encode("utf-8")]
        word[-1] += "</w>"
        while len(word) > 1:
            pairs = [(ranks.get((a, b), 1 << 30), a, b) for a, b in zip(word, word[1:])]
            rank, first, second = min(pairs)
            if rank == 1 << 30:
                break
            merged, i = [], 0
            while i < len(word):
                if i + 1 < len(word) and word[i] == first and word[i + 1] == second:
                    merged.append(first + second)
                    i += 2
                else:
                    merged.append(word[i])
                    i += 1
            word = merged
        out += [ids[w] for w in word]
    out.append(ids["<|endoftext|>"])
    if len(out) > context:
        out = out[:context]
        out[-1] = ids["<|endoftext|>"]
    return out + [0] * (context - len(out))


def make_tokenizer_cases(out):
    merges = train_merges(300)
    with open(os.path.join(out, "bpe_trained.txt"), "w", encoding="utf-8") as f:
        f.write("#version: 0.2 (make_stage_test_models.py)\n")
        f.writelines(f"{a} {b}\n" for a, b in merges)
    texts = ["A photo of a RED car parked on the street.", "it's the bus's stop, isn't it? they're here",
             "  traffic   cones\tand\nbarriers!!! ", "truck #42 at 10:35 on highway A7", "snake_case_name + x=y",
             "caf\u00e9 na\u00efve \u00fcber stra\u00dfe", "<|endoftext|> after the end", "U.S.A. vs. e.g. i.e.",
             " ".join(["pedestrians crossing"] * 30)]
    with open(os.path.join(out, "tokenizer_cases.json"), "w", encoding="utf-8") as f:
        json.dump([{"text": t, "ids": reference_tokenize(t, merges)} for t in texts], f, ensure_ascii=False)


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(11)
    make_clip(out)
    make_normals(out)
    make_lrm(out)
    make_harmonizer(out)
    make_tokenizer_cases(out)
    print(f"make_stage_test_models: wrote the CLIP, normal, LRM and harmoniser test models to {out}")


if __name__ == "__main__":
    main()
