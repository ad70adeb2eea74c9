// spml check-plugin LIB... [--json]: the contract suite (spml/check_plugin.h) on each library.
// One line per clause; exit 1 when any clause fails (a crashing plugin fails its clause).
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "commands.h"
#include "spml/check_plugin.h"
#include "spml/parse.h"

namespace spml::cli {
namespace {

// Each plugin is checked in a child process, so that a plugin that crashes, exits or hangs fails
// the clause it was in and the checker goes on with the next, its summary and --json intact.
// The child sends one JSON line when a clause starts ({"running": ...}), one when it ends (the
// clause), and a last one when it is done ({"kind": ...}); a child that ends without that last
// line ended inside the clause that started last.
int g_clause_fd = -1;
// Per plugin (one child): generous for the torch library's BNN at its defaults on 2 cores.
constexpr int kDefaultTimeout = 600;

void write_all(int fd, const std::string& text) {
  for (size_t done = 0; done < text.size();) {
    const ssize_t n = write(fd, text.data() + done, text.size() - done);
    if (n <= 0) return;
    done += static_cast<size_t>(n);
  }
}

check::Verdict verdict_of(const std::string& word) {
  return word == "PASS" ? check::Verdict::kPass : word == "FAIL" ? check::Verdict::kFail : check::Verdict::kSkip;
}

// One child: a library, or one plugin of it (options.only_plugin).
struct Job {
  std::string file;
  check::CheckOptions options;
  pid_t pid = -1;
  int fd = -1;
  std::string text;   // the lines it sent
  int status = 0;
  std::chrono::steady_clock::time_point started, deadline;
  double seconds = 0;   // wall time, start to end, as the parent saw it
  bool timed_out = false;
};

// What a plugin prints goes to stderr, in the parent (libraries are loaded there to list their
// plugins) as in the children, so that stdout holds only the checker's lines or --json document.
class StdoutToStderr {
 public:
  StdoutToStderr() : saved_((std::cout.flush(), std::fflush(stdout), dup(STDOUT_FILENO))) { dup2(STDERR_FILENO, STDOUT_FILENO); }
  ~StdoutToStderr() {
    std::fflush(stdout);
    if (saved_ >= 0) dup2(saved_, STDOUT_FILENO), close(saved_);
  }
  StdoutToStderr(const StdoutToStderr&) = delete;
  StdoutToStderr& operator=(const StdoutToStderr&) = delete;

 private:
  int saved_;
};

// The child's part: runs check_library(job.file), sending its lines; never returns.
[[noreturn]] void child(Job& job, int fd) {
  g_clause_fd = fd;
  dup2(STDERR_FILENO, STDOUT_FILENO);
  // A plugin that calls exit(): end at once with its status, running none of the parent's
  // atexit work (nor a leak check of a process cut off mid-clause).
  on_exit([](int status, void*) { _exit(status); }, nullptr);
  job.options.on_start = [](const std::string& plugin, const std::string& clause) {
    write_all(g_clause_fd, nlohmann::json{{"running", {{"plugin", plugin}, {"clause", clause}}}}.dump() + "\n");
  };
  job.options.on_clause = [](const check::Clause& c) {
    check::LibraryReport one;
    one.clauses.push_back(c);
    write_all(g_clause_fd, check::to_json(one)["clauses"][0].dump() + "\n");
  };
  const check::LibraryReport r = check::check_library(job.file, job.options);
  write_all(g_clause_fd, nlohmann::json{{"kind", r.kind}, {"seconds", r.seconds}}.dump() + "\n");
  _exit(0);
}

// Forks the child that runs check_library(job.file) and sends its clause lines.
void start(Job& job, double timeout) {
  int fds[2];
  if (pipe(fds) != 0) throw std::runtime_error("check-plugin: cannot create a pipe");
  std::cout.flush();
  std::fflush(stdout);
  job.pid = fork();
  if (job.pid < 0) throw std::runtime_error("check-plugin: cannot fork");
  if (job.pid == 0) {
    close(fds[0]);
    child(job, fds[1]);
  }
  close(fds[1]);
  job.fd = fds[0];
  job.started = std::chrono::steady_clock::now();
  job.deadline = job.started + std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(timeout));
}

// Why a child that did not send its last line ended: killed at the time limit, a signal, or an exit.
std::string how_it_ended(const Job& job, double timeout, bool in_clause) {
  if (job.timed_out)
    return "did not finish within the time limit of " + number_text(timeout, 6) + " s per plugin (--timeout); the check was stopped";
  if (WIFSIGNALED(job.status)) return "the plugin crashed (signal " + std::to_string(WTERMSIG(job.status)) + ")";
  return "the process exited with status " + std::to_string(WIFEXITED(job.status) ? WEXITSTATUS(job.status) : job.status) +
         (in_clause ? " before the clause finished" : " before reporting every clause");
}

// The report a finished child sent, rebuilt from its lines; a child that ended early fails the
// clause it was in (or a "process" clause when none had started).
check::LibraryReport report_of(const Job& job, double timeout) {
  check::LibraryReport r;
  r.file = job.file;
  bool done = false;
  std::string plugin, clause;   // the clause started and not yet finished
  std::istringstream lines(job.text);
  for (std::string line; std::getline(lines, line);) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded()) continue;
    if (j.contains("running")) {
      plugin = j["running"]["plugin"], clause = j["running"]["clause"];
    } else if (j.contains("clause")) {
      r.clauses.push_back({j["plugin"], j["clause"], verdict_of(j["verdict"]), j["detail"]});
      clause.clear();
    } else if (j.contains("kind")) {
      r.kind = j["kind"], r.seconds = j["seconds"], done = true;
    }
  }
  if (!done) {
    r.seconds = job.seconds;
    const bool in_clause = !clause.empty();
    r.clauses.push_back({in_clause ? plugin : "", in_clause ? clause : "process", check::Verdict::kFail, how_it_ended(job, timeout, in_clause)});
  } else if (!(WIFEXITED(job.status) && WEXITSTATUS(job.status) == 0)) {
    r.clauses.push_back({"", "process", check::Verdict::kFail, "the check ended abnormally (status " + std::to_string(job.status) + ")"});
  }
  return r;
}

// Runs the jobs, at most `parallel` children at a time, reading every running child's pipe as
// it writes (a full pipe would stop a child); a child past its deadline is killed.
void run_jobs(std::vector<Job>& jobs, size_t parallel, double timeout) {
  size_t next = 0;
  std::vector<Job*> active;
  auto finish = [](Job* j) {   // the pipe closed (the child ended, or closed it and runs on)
    close(j->fd);
    j->fd = -1;
    while (waitpid(j->pid, &j->status, WNOHANG) == 0) {
      if (std::chrono::steady_clock::now() >= j->deadline) {
        kill(j->pid, SIGKILL);
        j->timed_out = true;
        waitpid(j->pid, &j->status, 0);
        break;
      }
      usleep(10000);
    }
    j->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - j->started).count();
  };
  while (next < jobs.size() || !active.empty()) {
    while (active.size() < parallel && next < jobs.size()) {
      start(jobs[next], timeout);
      active.push_back(&jobs[next++]);
    }
    const auto now = std::chrono::steady_clock::now();
    auto first_deadline = active.front()->deadline;
    for (Job* j : active) first_deadline = std::min(first_deadline, j->deadline);
    const auto wait_ms = std::chrono::duration_cast<std::chrono::milliseconds>(first_deadline - now).count() + 1;
    std::vector<pollfd> fds;
    for (Job* j : active) fds.push_back({j->fd, POLLIN, 0});
    if (poll(fds.data(), fds.size(), static_cast<int>(std::clamp<long long>(wait_ms, 0, 60000))) < 0 && errno != EINTR)
      throw std::runtime_error("check-plugin: poll failed");
    for (size_t k = 0; k < fds.size(); ++k) {
      Job* j = active[k];
      if (fds[k].revents & (POLLIN | POLLHUP | POLLERR)) {
        char buf[4096];
        const ssize_t n = read(j->fd, buf, sizeof buf);
        if (n > 0) j->text.append(buf, static_cast<size_t>(n));
        else finish(j);
      } else if (std::chrono::steady_clock::now() >= j->deadline) {
        kill(j->pid, SIGKILL);
        j->timed_out = true;
        finish(j);
      }
    }
    active.erase(std::remove_if(active.begin(), active.end(), [](Job* j) { return j->fd < 0; }), active.end());
  }
}

// Every library's report: each plugin checked in a child of its own, two children at a time
// (the 2-core reference machine); the library's own clauses are taken from its first child.
std::vector<check::LibraryReport> check_all(const std::vector<std::string>& files, const check::CheckOptions& options, double timeout) {
  std::vector<Job> jobs;
  std::vector<std::pair<size_t, size_t>> range;   // per file: its jobs [first, last)
  for (const auto& f : files) {
    const size_t first = jobs.size();
    std::vector<std::string> names;
    {
      StdoutToStderr quiet;
      names = check::plugin_names(f);
    }
    auto add = [&](const std::string& only) {
      Job j;
      j.file = f;
      j.options = options;
      j.options.only_plugin = only;
      jobs.push_back(std::move(j));
    };
    if (names.empty()) add("");
    for (const auto& n : names) add(n);
    range.emplace_back(first, jobs.size());
  }
  run_jobs(jobs, 2, timeout);
  std::vector<check::LibraryReport> out;
  for (size_t i = 0; i < files.size(); ++i) {
    check::LibraryReport r;
    r.file = files[i];
    for (size_t k = range[i].first; k < range[i].second; ++k) {
      const check::LibraryReport part = report_of(jobs[k], timeout);
      for (const auto& c : part.clauses)
        if (k == range[i].first || !c.plugin.empty() || c.name == "process") r.clauses.push_back(c);
      if (r.kind.empty()) r.kind = part.kind;
      r.seconds += part.seconds;
    }
    if (r.kind.empty()) {   // every child ended early: the kind is the library's, told here
      StdoutToStderr quiet;
      r.kind = check::library_kind(files[i]);
    }
    out.push_back(std::move(r));
  }
  return out;
}

}  // namespace

void add_check_plugin(CLI::App& app) {
  auto* cmd = app.add_subcommand("check-plugin", "Run the plugin contract suite on learner or force-plugin libraries");
  auto files = std::make_shared<std::vector<std::string>>();
  auto json = std::make_shared<bool>(false);
  auto seed = std::make_shared<std::string>("1");
  cmd->add_option("LIB", *files, "Plugin library files (.so), learner or force plugin")->required()->check(CLI::ExistingFile);
  cmd->add_flag("--json", *json, "Print one JSON document instead of lines");
  cmd->add_option("--seed", *seed, "Seed of the synthetic data and states (default 1)");
  auto sets = std::make_shared<std::vector<std::string>>();
  cmd->add_option("--set", *sets, "KEY=VALUE for every plugin that has the key (e.g. steps=300 for a faster BNN check); repeatable")
      ->allow_extra_args(false);   // one KEY=VALUE per --set, the option given as often as needed
  auto timeout = std::make_shared<std::string>(std::to_string(kDefaultTimeout));
  cmd->add_option("--timeout", *timeout, "Seconds one plugin's check may take before it is stopped and fails (default " +
                                             std::to_string(kDefaultTimeout) + ")");
  cmd->callback([=] {
    check::CheckOptions options;
    options.seed = seed_option("--seed", *seed);
    const double limit = finite_option("--timeout", *timeout, 0.0, 1e6, true);
    for (const auto& kv : *sets) {
      const auto eq = kv.find('=');
      if (eq == std::string::npos || eq == 0) throw CLI::ValidationError("--set", "'" + kv + "': expected key=value");
      for (const auto& [k, v] : options.config)
        if (k == kv.substr(0, eq)) throw CLI::ValidationError("--set", "key '" + k + "' given twice (" + k + "=" + v + ", " + kv + ")");
      options.config.emplace_back(kv.substr(0, eq), kv.substr(eq + 1));
    }
    std::vector<std::string> absolute;
    for (const auto& f : *files) absolute.push_back(std::filesystem::absolute(f).string());
    // One intra-op thread per child, set before any library (and its OpenMP runtime) is loaded:
    // two children run at a time, and a thread pool per child spins on a loaded machine.
    setenv("OMP_NUM_THREADS", "1", 1);
    setenv("MKL_NUM_THREADS", "1", 1);
    std::string why;
    {
      StdoutToStderr quiet;
      why = check::config_problem(absolute, options.config);
    }
    if (!why.empty()) throw CLI::ValidationError("--set", why);
    const auto t0 = std::chrono::steady_clock::now();
    nlohmann::json libraries = nlohmann::json::array();
    int failed = 0, clauses = 0;
    for (const check::LibraryReport& r : check_all(absolute, options, limit)) {
      if (!*json) std::cout << r.file << std::endl;
      for (const auto& c : r.clauses) {
        if (!*json) std::cout << "  " << check::clause_line(c) << "\n";
        ++clauses;
        if (c.verdict == check::Verdict::kFail) ++failed;
      }
      if (*json) libraries.push_back(check::to_json(r));
      else std::cout << "  " << (r.passed() ? "passed" : "FAILED") << " (" << (r.kind.empty() ? "kind unknown" : r.kind) << ", " << number_text(r.seconds, 3) << " s)\n";
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (*json)
      std::cout << json_output(nlohmann::json{{"libraries", libraries}, {"clauses", clauses}, {"failed", failed}, {"seconds", seconds}},
                               "check-plugin --json");
    else
      std::cout << files->size() << " libraries, " << clauses << " clauses, " << failed << " failed, in " << number_text(seconds, 3) << " s\n";
    if (failed) throw std::runtime_error("check-plugin: " + std::to_string(failed) + " of " + std::to_string(clauses) + " clauses failed");
  });
}

}  // namespace spml::cli
