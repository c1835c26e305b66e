// bench_remesh: one ContinuousRemesher::Remesh() pass (collapse / split / flip / relax) and one Step() at about
// 10k faces — the per-step cost of refinement's remeshing (refine.md). Google Benchmark.
//
// Icosphere(5) (20480 faces, edges ~0.038) is coarsened to a uniform target of 0.062 by 60 rounds of step +
// remesh, which settles at about 9k faces; each step pulls the vertices onto the unit sphere with a little
// noise (so edges keep moving, as in refinement). The timed loops then continue the same way.
// BM_Remesh10kFaces also reports what a pass did, per pass (RemeshStats): splits, collapses, flips and the
// wanted collapses / flips refused (counters), and those refusals by reason (label).
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "geometry/remesh.h"
#include "geometry/test_meshes.h"

namespace {

using sd::geometry::ContinuousRemesher;
using sd::geometry::RemeshOptions;
using sd::geometry::RemeshStats;

std::vector<Eigen::Vector3f> PullToSphere(const ContinuousRemesher& remesher, std::mt19937* rng) {
  std::normal_distribution<float> noise(0.0f, 1.0f);
  std::vector<Eigen::Vector3f> grad(remesher.positions().size());
  for (size_t v = 0; v < grad.size(); ++v)
    grad[v] = remesher.positions()[v] - remesher.positions()[v].normalized() +
              0.01f * Eigen::Vector3f(noise(*rng), noise(*rng), noise(*rng));
  return grad;
}

ContinuousRemesher SettledSphere(std::mt19937* rng) {
  const sd::TriangleMesh sphere = sd::geometry::testing::Icosphere(5);
  RemeshOptions options;
  options.edge_length_min = 0.062f;
  options.edge_length_max = 0.062f;
  ContinuousRemesher remesher(sphere.positions, sphere.faces, options);
  for (int round = 0; round < 60; ++round) {
    remesher.Step(PullToSphere(remesher, rng));
    remesher.Remesh();
  }
  return remesher;
}

void BM_Remesh10kFaces(benchmark::State& state) {
  std::mt19937 rng(9);
  ContinuousRemesher remesher = SettledSphere(&rng);
  size_t faces = 0, n = 0;
  RemeshStats total;
  for (auto _ : state) {
    state.PauseTiming();
    remesher.Step(PullToSphere(remesher, &rng));
    state.ResumeTiming();
    total += remesher.Remesh();
    faces += remesher.faces().size();
    ++n;
  }
  const double passes = static_cast<double>(n);
  state.counters["faces"] = static_cast<double>(faces) / passes;
  state.counters["splits"] = total.splits / passes;
  state.counters["collapses"] = total.collapses / passes;
  state.counters["flips"] = total.flips / passes;
  state.counters["collapse_rejected"] = total.collapse_rejected.Total() / passes;
  state.counters["flip_rejected"] = total.flip_rejected.Total() / passes;
  auto per_pass = [&](int count) { return std::to_string(static_cast<int>(count / passes + 0.5)); };
  const RemeshStats::Rejections& c = total.collapse_rejected;
  const RemeshStats::Rejections& f = total.flip_rejected;
  state.SetLabel("collapse rejected: boundary " + per_pass(c.boundary) + " link " + per_pass(c.link) + " valence " +
                 per_pass(c.valence) + " sliver " + per_pass(c.sliver) + " fold_over " + per_pass(c.fold_over) +
                 " too_long " + per_pass(c.too_long) + "; flip rejected: link " + per_pass(f.link) + " valence " +
                 per_pass(f.valence) + " sliver " + per_pass(f.sliver) + " fold_over " + per_pass(f.fold_over));
}
BENCHMARK(BM_Remesh10kFaces)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_Step10kFaces(benchmark::State& state) {
  std::mt19937 rng(9);
  ContinuousRemesher remesher = SettledSphere(&rng);
  for (auto _ : state) {
    state.PauseTiming();
    const std::vector<Eigen::Vector3f> grad = PullToSphere(remesher, &rng);
    state.ResumeTiming();
    remesher.Step(grad);
  }
  state.counters["faces"] = static_cast<double>(remesher.faces().size());
}
BENCHMARK(BM_Step10kFaces)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
