#include "cli/slurm_job.h"

#include <poll.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>

#include "core/error.h"

extern char** environ;

namespace sd::cli {

namespace {

bool StartsWith(std::string_view s, std::string_view prefix) { return s.substr(0, prefix.size()) == prefix; }

bool IsOption(std::string_view arg, std::string_view name) {
  return arg == name || StartsWith(arg, std::string(name) + "=");
}

bool HasOption(const std::vector<std::string>& command, std::string_view name) {
  return std::any_of(command.begin(), command.end(), [&](const std::string& a) { return IsOption(a, name); });
}

// A value that goes into a #SBATCH line: sbatch splits those lines at white space and reads % as a pattern.
void CheckSbatchValue(const char* what, const std::string& value, bool allow_percent = true) {
  for (char c : value)
    if (std::isspace(static_cast<unsigned char>(c)) || c == '\0' || (!allow_percent && c == '%'))
      throw InputError({}, Msg() << "slurm submit: " << what << " '" << value
                                 << "' holds white space" << (allow_percent ? "" : " or %")
                                 << ", which an #SBATCH line cannot carry");
}

bool AllDigits(std::string_view s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// "0-3,7,9-11%2" (an array's task list, with an optional throttle) into `out`; false if malformed.
bool ExpandTaskRange(std::string_view list, std::vector<int>& out) {
  list = list.substr(0, list.find('%'));
  while (!list.empty()) {
    const size_t comma = list.find(',');
    const std::string_view part = list.substr(0, comma);
    list = comma == std::string_view::npos ? std::string_view() : list.substr(comma + 1);
    const size_t dash = part.find('-');
    const std::string_view lo = part.substr(0, dash);
    const std::string_view hi = dash == std::string_view::npos ? lo : part.substr(dash + 1);
    if (!AllDigits(lo) || !AllDigits(hi) || lo.size() > 9 || hi.size() > 9) return false;
    const int a = std::stoi(std::string(lo)), b = std::stoi(std::string(hi));
    if (b < a) return false;
    for (int i = a; i <= b; ++i) out.push_back(i);
  }
  return true;
}

}  // namespace

void CheckShardableCommand(const std::vector<std::string>& command) {
  if (command.empty())
    throw InputError({}, "slurm submit: give the batch command after --, e.g. -- mine index --log LOG --out DIR");
  if (HasOption(command, "--shard"))
    throw InputError({}, "slurm submit: the command already has --shard; each array task adds its own --shard K/N");
  const std::string& sub = command[0];
  if (sub == "synth" && HasOption(command, "--merge"))
    throw InputError({}, "slurm submit: synth --merge runs once, after the array has finished: run it directly");
  const bool ok = (sub == "mine" && command.size() > 1 && command[1] == "index") ||
                  (sub == "generate" && HasOption(command, "--manifest")) || sub == "synth";
  if (!ok) {
    std::string shown = sub;
    if (command.size() > 1 && !StartsWith(command[1], "-")) shown += " " + command[1];
    throw InputError({}, Msg() << "slurm submit: '" << shown
                               << "' is not a batch command taking --shard (mine index, generate --manifest, synth)");
  }
}

std::string ShellQuote(std::string_view text) {
  const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](char c) {
    return c != '\0' && (std::isalnum(static_cast<unsigned char>(c)) || std::strchr("@%+=:,./_-", c) != nullptr);
  });
  if (plain) return std::string(text);
  std::string q = "'";
  for (char c : text) {
    if (c == '\'')
      q += "'\\''";
    else
      q += c;
  }
  q += '\'';
  return q;
}

std::string MakeSlurmScript(const SlurmJobSpec& spec) {
  CheckShardableCommand(spec.command);
  SD_CHECK(spec.binary.is_absolute() && spec.log_dir.is_absolute() && spec.work_dir.is_absolute(),
           << spec.binary << " " << spec.log_dir << " " << spec.work_dir);
  if (spec.shards < 1) throw InputError({}, Msg() << "slurm submit: --shards must be at least 1, not " << spec.shards);
  if (spec.cpus_per_task < 1)
    throw InputError({}, Msg() << "slurm submit: --cpus-per-task must be at least 1, not " << spec.cpus_per_task);
  if (spec.job_name.empty() || spec.job_name.find('/') != std::string::npos)
    throw InputError({}, Msg() << "slurm submit: --job-name '" << spec.job_name << "' must be a non-empty file name");
  CheckSbatchValue("--job-name", spec.job_name, false);
  CheckSbatchValue("--log-dir", spec.log_dir.string(), false);
  CheckSbatchValue("--partition", spec.partition);
  CheckSbatchValue("--time", spec.time);
  CheckSbatchValue("--mem", spec.mem);
  for (const std::string& arg : spec.sbatch_args) {
    for (char c : arg)
      if (c == '\n' || c == '\r' || c == '\0')
        throw InputError({}, Msg() << "slurm submit: --sbatch-arg holds a line break");
    if (!StartsWith(arg, "-"))
      throw InputError({}, Msg() << "slurm submit: --sbatch-arg '" << arg << "' is not an sbatch option (--name=value)");
    if (IsOption(arg, "--array") || StartsWith(arg, "-a"))
      throw InputError({}, Msg() << "slurm submit: --sbatch-arg '" << arg << "': the array is --shards");
  }

  const std::string n = std::to_string(spec.shards);
  std::string cmd;
  for (const std::string& a : spec.command) {
    cmd += ' ';
    cmd += ShellQuote(a);
  }
  std::string s;
  s += "#!/bin/bash\n";
  s += "# Written by `synthdrive slurm submit`: array task K runs shard K/" + n + " of\n";
  s += "#   synthdrive" + cmd + "\n";
  s += "# `sbatch` this file again to rerun failed or missing shards: finished items are skipped (docs/scale.md).\n";
  s += "#SBATCH --job-name=" + spec.job_name + "\n";
  s += "#SBATCH --array=0-" + std::to_string(spec.shards - 1) + "\n";
  s += "#SBATCH --output=" + (spec.log_dir / (spec.job_name + "-%A_%a.out")).string() + "\n";
  s += "#SBATCH --cpus-per-task=" + std::to_string(spec.cpus_per_task) + "\n";
  if (!spec.partition.empty()) s += "#SBATCH --partition=" + spec.partition + "\n";
  if (!spec.time.empty()) s += "#SBATCH --time=" + spec.time + "\n";
  if (!spec.mem.empty()) s += "#SBATCH --mem=" + spec.mem + "\n";
  for (const std::string& arg : spec.sbatch_args) s += "#SBATCH " + arg + "\n";
  s += "set -euo pipefail\n";
  s += ": \"${SLURM_ARRAY_TASK_ID:?submit this script with sbatch}\"\n";
  s += "cd " + ShellQuote(spec.work_dir.string()) + "\n";
  s += "echo \"synthdrive slurm: shard ${SLURM_ARRAY_TASK_ID}/" + n +
       " of job ${SLURM_ARRAY_JOB_ID} on $(hostname) at $(date -u +%Y-%m-%dT%H:%M:%SZ)\" >&2\n";
  s += "exec " + ShellQuote(spec.binary.string()) + " --threads " + std::to_string(spec.cpus_per_task) + cmd +
       " --shard \"${SLURM_ARRAY_TASK_ID}/" + n + "\"\n";
  return s;
}

std::string ParseSbatchJobId(std::string_view output) {
  std::string_view s = output;
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
  while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
  const std::string_view id = s.substr(0, s.find(';'));
  if (!AllDigits(id))
    throw InputError({}, Msg() << "slurm submit: sbatch --parsable printed '" << std::string(s) << "', not a job id");
  return std::string(id);
}

const char* TaskStateName(TaskState state) {
  switch (state) {
    case TaskState::kPending: return "PENDING";
    case TaskState::kRunning: return "RUNNING";
    case TaskState::kCompleted: return "COMPLETED";
    case TaskState::kFailed: return "FAILED";
  }
  return "?";
}

TaskState ClassifySlurmState(std::string_view slurm_state) {
  std::string s(slurm_state.substr(0, slurm_state.find(' ')));  // "CANCELLED by 0"
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  while (!s.empty() && s.back() == '+') s.pop_back();  // sacct's "CANCELLED+"
  if (s == "COMPLETED") return TaskState::kCompleted;
  for (const char* p : {"PENDING", "REQUEUED", "REQUEUE_FED", "REQUEUE_HOLD", "RESV_DEL_HOLD", "CONFIGURING"})
    if (s == p) return TaskState::kPending;
  // Started and not finished yet; COMPLETING means the exit status is not final until it ends.
  for (const char* p : {"RUNNING", "COMPLETING", "SUSPENDED", "STOPPED", "SIGNALING", "STAGE_OUT", "RESIZING"})
    if (s == p) return TaskState::kRunning;
  // FAILED, CANCELLED, TIMEOUT, NODE_FAIL, OUT_OF_MEMORY, PREEMPTED, BOOT_FAIL, DEADLINE, REVOKED, SPECIAL_EXIT
  // and any state this code does not know: not a success.
  return TaskState::kFailed;
}

void ReadSlurmTaskLines(std::string_view text, const std::string& job_id, std::map<int, TaskStatus>& tasks) {
  const std::string prefix = job_id + "_";
  while (!text.empty()) {
    const size_t eol = text.find('\n');
    std::string_view line = text.substr(0, eol);
    text = eol == std::string_view::npos ? std::string_view() : text.substr(eol + 1);
    while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.remove_suffix(1);
    const size_t bar = line.find('|');
    if (bar == std::string_view::npos) continue;
    const std::string_view id = line.substr(0, bar);
    const std::string_view state = line.substr(bar + 1, line.find('|', bar + 1) - bar - 1);
    if (!StartsWith(id, prefix) || state.empty()) continue;
    const std::string_view task = id.substr(prefix.size());
    std::vector<int> ids;
    if (AllDigits(task) && task.size() <= 9) {
      ids.push_back(std::stoi(std::string(task)));
    } else if (task.size() >= 2 && task.front() == '[' && task.back() == ']') {
      if (!ExpandTaskRange(task.substr(1, task.size() - 2), ids)) continue;
    } else {
      continue;  // a job step ("12_3.batch") or something else
    }
    for (int i : ids) tasks[i] = TaskStatus{ClassifySlurmState(state), std::string(state)};
  }
}

ProcessResult RunProcess(const std::vector<std::string>& argv) {
  SD_CHECK(!argv.empty(), << "no program");
  ProcessResult result;
  int out_pipe[2], err_pipe[2];
  if (pipe(out_pipe) != 0) return result;
  if (pipe(err_pipe) != 0) {
    close(out_pipe[0]);
    close(out_pipe[1]);
    return result;
  }
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, out_pipe[1], STDOUT_FILENO);
  posix_spawn_file_actions_adddup2(&actions, err_pipe[1], STDERR_FILENO);
  for (int fd : {out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]}) posix_spawn_file_actions_addclose(&actions, fd);
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  close(out_pipe[1]);
  close(err_pipe[1]);
  if (rc != 0) {
    close(out_pipe[0]);
    close(err_pipe[0]);
    result.exit_code = 127;
    result.err = std::string("cannot run ") + argv[0] + ": " + std::strerror(rc);
    return result;
  }
  // Both pipes at once: a child blocked on a full stderr pipe would never close its stdout.
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* sinks[2] = {&result.out, &result.err};
  int open_fds = 2;
  char buf[4096];
  while (open_fds > 0) {
    if (poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || fds[i].revents == 0) continue;
      const ssize_t got = read(fds[i].fd, buf, sizeof buf);
      if (got > 0) {
        sinks[i]->append(buf, static_cast<size_t>(got));
      } else if (got == 0 || errno != EINTR) {
        close(fds[i].fd);
        fds[i].fd = -1;
        --open_fds;
      }
    }
  }
  for (const pollfd& f : fds)
    if (f.fd >= 0) close(f.fd);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
  return result;
}

}  // namespace sd::cli
