#!/usr/bin/env python3
"""CLIP ViT-B/32 on its real architecture through SynthDrive's runtime and tokenizer, against the Python model.

No weights can be had, but the architecture can: transformers' CLIPModel from its default config (ViT-B/32) with
random weights, exported by tools/export/export_clip.py (--backend transformers), run by bench/bench_clip.cpp (the
C++ tokenizer on CLIP's real BPE vocabulary, the TorchScript runtime on cpu, cuda and cuda float16), and compared
with the eager Python model on the same pixels and on the token ids CLIP's own tokenizer gives
(reference_tokens.json):
  * token ids: the C++ tokenizer's rows against the reference ids (sot, ids, eot, zeros);
  * embeddings: cosine of each C++ embedding with the Python one (target >= 0.9999 in float32);
  * retrieval: each prompt's top-5 images, and each image's top-5 neighbours, C++ against Python;
  * preprocessing: C++ resize + crop of the full images against PIL's (the reference pipeline's);
  * throughput: images/s of the C++ runtime (embed = preprocessing + forward, forward alone) and of the eager
    Python model, float32 and float16.

Usage: clip_check.py --bench BENCH_CLIP --vocab bpe_simple_vocab_16e6.txt.gz --reference reference_tokens.json
                     --out DIR PHOTO...
Writes DIR/clip_check.json and prints a summary. Needs torch, transformers and PIL (the GPU machine's Python).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np
import torch
from PIL import Image

sys.path.insert(0, os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "export"))
import export_clip  # noqa: E402

TOP_K = 5


def reference_pixels(image, size):
    """OpenAI's preprocess: shorter side to `size` (PIL bicubic), centre crop; 0..1 float, HWC."""
    w, h = image.size
    # torchvision's Resize(int): the longer side scaled alike and truncated.
    rw, rh = (size, max(size, int(size * h / w))) if w <= h else (max(size, int(size * w / h)), size)
    image = image.resize((rw, rh), Image.BICUBIC)
    x0, y0 = int(round((rw - size) / 2.0)), int(round((rh - size) / 2.0))
    return image.crop((x0, y0, x0 + size, y0 + size))


def retrieval_set(photos, folder, size):
    """Each photo whole and its four quadrants: the raw crops (for the C++ preprocessing) and the reference
    preprocessed 224 × 224 ones (the same pixels into both models)."""
    raw, pre = [], []
    os.makedirs(folder, exist_ok=True)
    for p, photo in enumerate(photos):
        image = Image.open(photo).convert("RGB")
        w, h = image.size
        crops = [image] + [image.crop((x, y, x + w // 2, y + h // 2)) for y in (0, h // 2) for x in (0, w // 2)]
        for c, crop in enumerate(crops):
            raw_file = os.path.join(folder, f"raw_{p:02d}_{c}.png")
            pre_file = os.path.join(folder, f"pre_{p:02d}_{c}.png")
            crop.save(raw_file)
            reference_pixels(crop, size).save(pre_file)
            raw.append(raw_file)
            pre.append(pre_file)
    return raw, pre


def read_rows(file, dim):
    return np.fromfile(file, dtype=np.float32).reshape(-1, dim)


def unit(x):
    return x / np.linalg.norm(x, axis=1, keepdims=True)


def top_k(queries, items, k):
    return np.argsort(-(queries @ items.T), axis=1, kind="stable")[:, :k]


def compare(cpp, ref):
    cos = np.sum(unit(cpp) * unit(ref), axis=1)
    return {"min_cosine": float(cos.min()), "median_cosine": float(np.median(cos)), "count": int(len(cos))}


def retrieval_agreement(cpp_img, cpp_txt, ref_img, ref_txt):
    t_cpp, t_ref = top_k(cpp_txt, cpp_img, TOP_K), top_k(ref_txt, ref_img, TOP_K)
    # Image -> image: leave the query itself out (its own row is always first).
    i_cpp, i_ref = top_k(cpp_img, cpp_img, TOP_K + 1)[:, 1:], top_k(ref_img, ref_img, TOP_K + 1)[:, 1:]
    return {
        "text_to_image_top1_same": float(np.mean(t_cpp[:, 0] == t_ref[:, 0])),
        "text_to_image_top5_same_order": float(np.mean(np.all(t_cpp == t_ref, axis=1))),
        "text_to_image_top5_same_set": float(np.mean([set(a) == set(b) for a, b in zip(t_cpp, t_ref)])),
        "image_to_image_top5_same_set": float(np.mean([set(a) == set(b) for a, b in zip(i_cpp, i_ref)])),
    }


def python_throughput(model, size, device, half, batch, count, repeats=3):
    enc = export_clip.ImageEncoder(model, export_clip.OPENAI_MEAN, export_clip.OPENAI_STD).to(device).eval()
    if half:
        enc = enc.half()
    x = torch.rand(batch, 3, size, size, device=device, dtype=torch.half if half else torch.float32)
    passes = max(1, count // batch)
    times = []
    with torch.inference_mode():
        for r in range(repeats + 1):
            torch.cuda.synchronize()
            t0 = time.perf_counter()
            for _ in range(passes):
                enc(x)
            torch.cuda.synchronize()
            if r:
                times.append(time.perf_counter() - t0)
    return passes * batch / statistics.median(times)


def run(cmd, log):
    print("$", " ".join(cmd), flush=True)
    done = subprocess.run(cmd, capture_output=True, text=True)
    log.write(done.stdout + done.stderr)
    print(done.stdout + done.stderr, flush=True)
    if done.returncode:
        sys.exit(f"clip_check: {cmd[0]} exited {done.returncode}")
    return done.stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bench", required=True)
    ap.add_argument("--vocab", required=True)
    ap.add_argument("--reference", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--throughput", type=int, default=4096, help="images per timed pass on the GPU")
    ap.add_argument("photos", nargs="+")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    work = "/tmp/clip_check"
    os.makedirs(work, exist_ok=True)
    log = open(os.path.join(args.out, "clip_check.log"), "w")
    torch.backends.cuda.matmul.allow_tf32 = False  # the runtime's own setting on CUDA (docs/gpu.md)
    torch.backends.cudnn.allow_tf32 = False
    result = {"torch": torch.__version__, "gpu": torch.cuda.get_device_name(0)}

    model_dir = os.path.join(work, "model")
    run([sys.executable, os.path.join(os.path.dirname(export_clip.__file__), "export_clip.py"), model_dir,
         "--backend", "transformers", "--pretrained", "random", "--seed", str(args.seed), "--vocab", args.vocab], log)
    model, mean, std, size, _, tokenize, source, _ = export_clip.load("transformers", "ViT-B-32", "random",
                                                                      args.vocab, args.seed)
    result["model"] = source
    context = model.context_length

    # Prompts and their reference ids from CLIP's own tokenizer. Texts with line breaks cannot travel as lines.
    reference = json.load(open(args.reference, encoding="utf-8"))
    cases = [c for c in reference["cases"] if "\n" not in c["text"] and "\r" not in c["text"]]
    ref_tokens = torch.zeros(len(cases), context, dtype=torch.int64)
    for row, case in enumerate(cases):
        ids = ([reference["sot"]] + case["bpe_ids"] + [reference["eot"]])[:context]
        ids[-1] = reference["eot"]
        ref_tokens[row, :len(ids)] = torch.tensor(ids)
    texts_file = os.path.join(work, "texts.txt")
    with open(texts_file, "w", encoding="utf-8") as f:
        f.write("".join(c["text"] + "\n" for c in cases))
    hf_tokens = tokenize([c["text"] for c in cases])
    result["prompts"] = len(cases)
    result["hf_tokenizer_rows_equal_reference"] = int((hf_tokens == ref_tokens).all(dim=1).sum())

    raw, pre = retrieval_set(args.photos, os.path.join(work, "images"), size)
    for name, files in (("raw", raw), ("pre", pre)):
        with open(os.path.join(work, f"{name}.txt"), "w") as f:
            f.write("\n".join(files) + "\n")
    result["images"] = len(pre)

    # The eager Python model on the GPU: the reference embeddings.
    device = torch.device("cuda")
    model = model.to(device)
    pixels = torch.stack([torch.from_numpy(np.asarray(Image.open(p).convert("RGB"), dtype=np.float32) / 255.0)
                          .permute(2, 0, 1) for p in pre]).to(device)
    norm = (pixels - torch.tensor(mean, device=device).view(1, 3, 1, 1)) / torch.tensor(std, device=device).view(1, 3, 1, 1)
    with torch.inference_mode():
        ref_img = model.encode_image(norm).float().cpu().numpy()
        ref_txt = model.encode_text(ref_tokens.to(device)).float().cpu().numpy()
        cpu_model = model.to("cpu")
        cpu_img = cpu_model.encode_image(norm.cpu()).numpy()
        model = cpu_model.to(device)
    result["python_cpu_vs_cuda_images"] = compare(cpu_img, ref_img)
    dim = ref_img.shape[1]

    # The C++ runtime on the same pixels (identity resize at 224) and the same prompts.
    prefix = os.path.join(work, "emb")
    run([args.bench, "--model", model_dir, "--images", os.path.join(work, "pre.txt"), "--texts", texts_file,
         "--out", prefix, "--devices", "cpu,cuda", "--half", "--throughput", "0"], log)
    cpp_tokens = np.fromfile(prefix + "_tokens.i32", dtype=np.int32).reshape(-1, context)
    result["cpp_tokenizer_rows_equal_reference"] = int(np.all(cpp_tokens == ref_tokens.numpy(), axis=1).sum())
    result["runs"] = {}
    for label in ("cpu", "cuda", "cuda_fp16"):
        img, txt = read_rows(f"{prefix}_{label}_images.f32", dim), read_rows(f"{prefix}_{label}_texts.f32", dim)
        result["runs"][label] = {"images": compare(img, ref_img), "texts": compare(txt, ref_txt),
                                 "retrieval": retrieval_agreement(img, txt, unit(ref_img), unit(ref_txt))}

    # The C++ preprocessing of the full crops against PIL's.
    run([args.bench, "--model", model_dir, "--images", os.path.join(work, "raw.txt"), "--out", prefix + "_raw",
         "--devices", "cuda", "--throughput", "0"], log)
    raw_img = read_rows(f"{prefix}_raw_cuda_images.f32", dim)
    result["cpp_preprocessing_vs_pil"] = compare(raw_img, ref_img)
    result["cpp_preprocessing_vs_pil"]["retrieval"] = retrieval_agreement(
        raw_img, read_rows(f"{prefix}_cuda_texts.f32", dim), unit(ref_img), unit(ref_txt))

    # Throughput: the C++ runtime, then the eager model.
    out = run([args.bench, "--model", model_dir, "--devices", "cuda", "--half", "--throughput", str(args.throughput),
               "--batches", "64,256,1024", "--repeats", "3"], log)
    out += run([args.bench, "--model", model_dir, "--devices", "cpu", "--throughput", "256", "--batches", "64",
                "--repeats", "2"], log)
    result["cpp_throughput"] = [line for line in out.splitlines() if "images/s" in line]
    result["python_throughput"] = {}
    for half in (False, True):
        for batch in (64, 256, 1024):
            key = f"{'fp16' if half else 'fp32'} batch {batch}"
            result["python_throughput"][key] = round(python_throughput(model, size, device, half, batch,
                                                                       args.throughput), 1)
    json.dump(result, open(os.path.join(args.out, "clip_check.json"), "w"), indent=1)
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
