#pragma once
// `synthdrive slurm`: a batch command's shards as one Slurm job array (docs/scale.md). SynthDrive never
// schedules anything itself (DESIGN.md): it writes an ordinary sbatch script whose array task K runs
// `<this binary> <command> --shard K/N`, hands it to `sbatch`, and reads the tasks' states back from
// `squeue` (finished jobs stay there MinJobAge seconds) and `sacct` (when the site has accounting).
// Rerunning the same script reruns the array; every batch command skips the items already done.
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace sd::cli {

struct SlurmJobSpec {
  std::filesystem::path binary;       // absolute path of the synthdrive binary the tasks run
  std::vector<std::string> command;   // subcommand and its arguments, e.g. {"mine", "index", "--log", ...}
  int shards = 1;                     // N: array tasks 0..N-1
  int cpus_per_task = 1;              // --cpus-per-task, also the task's --threads
  std::string partition, time, mem;   // empty: the site's default
  std::vector<std::string> sbatch_args;  // extra #SBATCH options, verbatim (e.g. "--account=perception")
  std::string job_name = "synthdrive";
  std::filesystem::path log_dir;      // absolute: <job_name>-<jobid>_<task>.out per task
  std::filesystem::path work_dir;     // absolute: the tasks' working directory (relative arguments resolve here)
};

// InputError unless `command` is a batch command that takes --shard (mine index, generate --manifest, synth)
// and does not already carry one.
void CheckShardableCommand(const std::vector<std::string>& command);

// The sbatch script for `spec` (validated: InputError on values that cannot go into a #SBATCH line).
std::string MakeSlurmScript(const SlurmJobSpec& spec);

// `text` as one POSIX shell word (single-quoted unless it is plainly safe).
std::string ShellQuote(std::string_view text);

// The job id from `sbatch --parsable` output ("1234" or "1234;cluster"); InputError when there is none.
std::string ParseSbatchJobId(std::string_view output);

enum class TaskState { kPending, kRunning, kCompleted, kFailed };
const char* TaskStateName(TaskState state);  // PENDING, RUNNING, COMPLETED, FAILED
// Slurm's job state names (PENDING, COMPLETING, OUT_OF_MEMORY, "CANCELLED by 0", ...) folded into four.
TaskState ClassifySlurmState(std::string_view slurm_state);

struct TaskStatus {
  TaskState state = TaskState::kPending;
  std::string slurm_state;  // as Slurm reported it
};

// Reads "<jobid>_<task>|<STATE>" lines (squeue -r -o '%i|%T', sacct -X -P -o JobID,State) for array job
// `job_id` into `tasks`; a pending range "<jobid>_[0-3,7%2]" expands to its tasks. Lines of other jobs, of job
// steps ("<jobid>_<task>.batch") and blank lines are ignored. Later calls overwrite earlier entries, so read
// sacct first and squeue (the live view) last.
void ReadSlurmTaskLines(std::string_view text, const std::string& job_id, std::map<int, TaskStatus>& tasks);

struct ProcessResult {
  int exit_code = -1;  // 127: could not be started
  std::string out, err;
};
// Runs argv[0] (looked up on PATH) with the rest as arguments, no shell, and captures stdout and stderr.
ProcessResult RunProcess(const std::vector<std::string>& argv);

}  // namespace sd::cli
