//! One command buffer and its fence for work the frame loop submits and collects
//! later without waiting (`DepthReadback`, `ImageUpload`): recorded and submitted
//! with the fence, polled by `busy`, which resets the fence once it has signalled,
//! so the buffer is re-recorded only after the GPU is done with it. Teardown
//! (`Drop`): wait for a submission in flight, then the fence and the buffer.
#![allow(unsafe_code)]

use super::{vkr, GpuContext, GpuError};
use ash::vk;

pub(crate) struct FencedCommand<'a> {
    ctx: &'a GpuContext,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    in_flight: bool,
}

impl<'a> FencedCommand<'a> {
    pub(crate) fn new(ctx: &'a GpuContext) -> Result<Self, GpuError> {
        let mut me = Self { ctx, cmd: vk::CommandBuffer::null(), fence: vk::Fence::null(), in_flight: false };
        me.cmd = ctx.allocate_command_buffer()?;
        // SAFETY: valid device; destroyed in `Drop`.
        me.fence =
            unsafe { ctx.device.create_fence(&vk::FenceCreateInfo::default(), None) }.map_err(vkr("vkCreateFence"))?;
        Ok(me)
    }

    /// Submitted and not yet seen finished by `busy` (or waited for).
    pub(crate) fn in_flight(&self) -> bool {
        self.in_flight
    }

    /// Whether the submission is still executing (polls its fence; never waits).
    /// False once it has finished: the fence is reset and the buffer free again.
    pub(crate) fn busy(&mut self) -> Result<bool, GpuError> {
        if !self.in_flight {
            return Ok(false);
        }
        let d = &self.ctx.device;
        // SAFETY: a fence of this device.
        if !unsafe { d.get_fence_status(self.fence) }.map_err(vkr("vkGetFenceStatus"))? {
            return Ok(true);
        }
        // SAFETY: signalled, so no pending submission uses it.
        unsafe { d.reset_fences(&[self.fence]) }.map_err(vkr("vkResetFences"))?;
        self.in_flight = false;
        Ok(false)
    }

    /// Record with `f` and submit with the fence. Refused while a submission is in
    /// flight (the caller checks `in_flight` or `busy` first).
    pub(crate) fn submit(&mut self, f: impl FnOnce(vk::CommandBuffer)) -> Result<(), GpuError> {
        if self.in_flight {
            return Err(GpuError::Input {
                input: "fenced command",
                problem: "the previous submission is in flight".into(),
            });
        }
        let d = &self.ctx.device;
        let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the command buffer is not pending (never submitted, or its fence
        // was seen signalled and reset); recorded, ended and submitted on this thread.
        unsafe {
            d.begin_command_buffer(self.cmd, &begin).map_err(vkr("vkBeginCommandBuffer"))?;
            f(self.cmd);
            d.end_command_buffer(self.cmd).map_err(vkr("vkEndCommandBuffer"))?;
            let submit = vk::SubmitInfo::default().command_buffers(std::slice::from_ref(&self.cmd));
            d.queue_submit(self.ctx.queue, &[submit], self.fence).map_err(vkr("vkQueueSubmit"))?;
        }
        self.in_flight = true;
        Ok(())
    }

    /// Block until a submission in flight is done (teardown, tests); it stays to be
    /// collected by `busy`.
    pub(crate) fn wait(&self) -> Result<(), GpuError> {
        if self.in_flight {
            // SAFETY: a fence of this device with a pending submission.
            unsafe { self.ctx.device.wait_for_fences(&[self.fence], true, u64::MAX) }
                .map_err(vkr("vkWaitForFences"))?;
        }
        Ok(())
    }
}

impl Drop for FencedCommand<'_> {
    fn drop(&mut self) {
        if self.wait().is_err() {
            // A lost device: nothing is executing any more either way.
            // SAFETY: valid device.
            let _ = unsafe { self.ctx.device.device_wait_idle() };
        }
        let d = &self.ctx.device;
        // SAFETY: nothing pending uses the command buffer or fence (waited above);
        // null handles (a failed `new`) are ignored by vkDestroy*/vkFree*.
        unsafe {
            d.destroy_fence(self.fence, None);
            if self.cmd != vk::CommandBuffer::null() {
                d.free_command_buffers(self.ctx.command_pool, &[self.cmd]);
            }
        }
    }
}
