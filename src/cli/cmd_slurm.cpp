// `synthdrive slurm submit|status`: a batch command's shards as one Slurm job array (docs/scale.md).
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "cli/slurm_job.h"
#include "core/error.h"
#include "core/log.h"
#include "io/files.h"

namespace sd::cli {

namespace {

namespace fs = std::filesystem;

std::string FirstLine(const std::string& text) {
  const size_t start = text.find_first_not_of(" \t\r\n");
  if (start == std::string::npos) return {};
  return text.substr(start, text.find('\n', start) - start);
}

void AddSubmitCommand(CLI::App& app, Runner& run) {
  struct Args {
    SlurmJobSpec spec;
    std::string log_dir = "slurm-logs", job_name;
    bool dry_run = false;
  };
  auto a = std::make_shared<Args>();
  SlurmJobSpec& s = a->spec;
  app.add_option("--shards", s.shards, "N: array tasks 0..N-1, task K runs --shard K/N")->required()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--partition", s.partition, "Slurm partition (default: the cluster's)");
  app.add_option("--time", s.time, "Time limit per task, e.g. 2:00:00");
  app.add_option("--mem", s.mem, "Memory per task, e.g. 16G");
  app.add_option("--cpus-per-task", s.cpus_per_task, "CPUs per task, also its --threads")->default_val(1)
      ->check(CLI::Range(1, 4096));
  app.add_option("--sbatch-arg", s.sbatch_args, "Extra sbatch option, written --sbatch-arg=--account=X (repeatable)");
  app.add_option("--job-name", a->job_name, "Job name and log/script file prefix (default: synthdrive-<command>)");
  app.add_option("--log-dir", a->log_dir, "Folder of the job script and the per-task logs")->default_val("slurm-logs");
  app.add_flag("--dry-run", a->dry_run, "Print the job script, submit nothing");
  app.add_option("command", s.command, "-- then the batch command and its arguments (no --shard)");
  run = [a]() {
    SlurmJobSpec spec = a->spec;
    CheckShardableCommand(spec.command);
    if (a->job_name.empty()) {
      spec.job_name = "synthdrive-" + spec.command[0];
      if (spec.command[0] == "mine") spec.job_name += "-" + spec.command[1];
    } else {
      spec.job_name = a->job_name;
    }
    std::error_code ec;
    spec.binary = fs::read_symlink("/proc/self/exe", ec);
    if (ec) throw InputError("/proc/self/exe", Msg() << "cannot find this binary: " << ec.message());
    spec.work_dir = fs::current_path();
    spec.log_dir = fs::absolute(a->log_dir).lexically_normal();
    const std::string script = MakeSlurmScript(spec);
    if (a->dry_run) {
      std::fputs(script.c_str(), stdout);
      return 0;
    }
    // The script lands under a name of its own, and takes the job's name once sbatch has given one, so it sits
    // next to its logs: <name>-<jobid>.sbatch, <name>-<jobid>_<K>.out.
    const fs::path pending = spec.log_dir / (spec.job_name + "-submit-" + std::to_string(getpid()) + ".sbatch");
    const bool had_log_dir = fs::exists(spec.log_dir);
    WriteFileAtomic(pending, script);
    const ProcessResult r = RunProcess({"sbatch", "--parsable", pending.string()});
    std::string job_id;
    try {
      if (r.exit_code != 0)
        throw InputError(pending, Msg() << "sbatch failed (exit " << r.exit_code << "): " << FirstLine(r.err));
      job_id = ParseSbatchJobId(r.out);
    } catch (...) {
      fs::remove(pending, ec);
      if (!had_log_dir) fs::remove(spec.log_dir, ec);  // only when still empty
      throw;
    }
    const fs::path script_path = spec.log_dir / (spec.job_name + "-" + job_id + ".sbatch");
    fs::rename(pending, script_path, ec);
    const fs::path kept = ec ? pending : script_path;
    std::printf("%s\n", job_id.c_str());
    std::fflush(stdout);
    SD_LOG(Info, "slurm: job " << job_id << ", " << spec.shards << " tasks; script " << kept.string() << "; logs "
                               << (spec.log_dir / (spec.job_name + "-" + job_id + "_K.out")).string()
                               << "; synthdrive slurm status " << job_id);
    return 0;
  };
}

void AddStatusCommand(CLI::App& app, Runner& run) {
  auto job_id = std::make_shared<std::string>();
  app.add_option("jobid", *job_id, "Array job id printed by slurm submit")->required();
  run = [job_id]() {
    const std::string id = *job_id;
    if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos)
      throw InputError({}, Msg() << "slurm status: '" << id << "' is not a job id (digits, as slurm submit prints)");
    std::map<int, TaskStatus> tasks;
    // sacct first (final states, when the site keeps accounting), then squeue: the live view, which also holds
    // finished tasks for MinJobAge seconds and is all there is without accounting.
    const ProcessResult sacct = RunProcess({"sacct", "-n", "-X", "-P", "-j", id, "-o", "JobID,State"});
    if (sacct.exit_code == 0) ReadSlurmTaskLines(sacct.out, id, tasks);
    const ProcessResult squeue = RunProcess({"squeue", "-h", "-r", "-t", "all", "-j", id, "-o", "%i|%T"});
    if (squeue.exit_code == 0) ReadSlurmTaskLines(squeue.out, id, tasks);
    if (sacct.exit_code == 127 && squeue.exit_code == 127)
      throw InputError({}, "slurm status: neither squeue nor sacct can be run here (no Slurm client on PATH)");
    if (tasks.empty())
      throw InputError({}, Msg() << "slurm status: job " << id << " is unknown to squeue"
                                 << (sacct.exit_code == 0 ? " and sacct" : " (and sacct has no accounting)")
                                 << (squeue.err.empty() ? "" : ": " + FirstLine(squeue.err)));
    int count[4] = {0, 0, 0, 0};
    for (const auto& [task, status] : tasks) {
      ++count[static_cast<int>(status.state)];
      const bool plain = status.slurm_state == TaskStateName(status.state);
      std::printf("%s_%d %s%s\n", id.c_str(), task, TaskStateName(status.state),
                  plain ? "" : (" (" + status.slurm_state + ")").c_str());
    }
    std::printf("job %s: %zu tasks: %d completed, %d running, %d pending, %d failed\n", id.c_str(), tasks.size(),
                count[static_cast<int>(TaskState::kCompleted)], count[static_cast<int>(TaskState::kRunning)],
                count[static_cast<int>(TaskState::kPending)], count[static_cast<int>(TaskState::kFailed)]);
    std::fflush(stdout);
    return count[static_cast<int>(TaskState::kFailed)] > 0 ? 1 : 0;
  };
}

}  // namespace

Runner AddSlurmCommand(CLI::App& app) {
  app.require_subcommand(1);
  auto submit_run = std::make_shared<Runner>();
  auto status_run = std::make_shared<Runner>();
  CLI::App* submit = app.add_subcommand("submit", "Write an sbatch job-array script for a batch command and submit it");
  CLI::App* status = app.add_subcommand("status", "Per-task state of a submitted job; exit 1 if a task failed");
  AddSubmitCommand(*submit, *submit_run);
  AddStatusCommand(*status, *status_run);
  return [submit, status, submit_run, status_run]() {
    if (submit->parsed()) return (*submit_run)();
    if (status->parsed()) return (*status_run)();
    return 1;
  };
}

}  // namespace sd::cli
